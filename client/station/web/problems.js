// The top bar's problem list (#problems): what went wrong, by key, with a count; a problem that
// is solved is cleared by its key. Kept in window.stevi.problems too.

import { el } from './util.js';
import { stevi } from './state.js';

const MAX_PROBLEMS = 50;

const problemCount = document.getElementById('problem-count');
const problemList = document.getElementById('problem-list');
const problemsBox = document.getElementById('problems');
const problemWord = document.getElementById('problem-word');

export function addProblem(key, message) {
  let p = stevi.problems.find((x) => x.key === key);
  if (p) {
    p.count += 1;
    p.message = message;
    p.time = new Date();
  } else {
    p = { key, message, count: 1, time: new Date() };
    stevi.problems.push(p);
    if (stevi.problems.length > MAX_PROBLEMS) stevi.problems.shift();
  }
  renderProblems();
}

export function clearProblem(key) {
  const i = stevi.problems.findIndex((x) => x.key === key);
  if (i >= 0) {
    stevi.problems.splice(i, 1);
    renderProblems();
  }
}

export function renderProblems() {
  problemCount.textContent = String(stevi.problems.length);
  problemWord.textContent = stevi.problems.length === 1 ? 'problem' : 'problems';
  problemsBox.dataset.count = String(stevi.problems.length);
  problemList.replaceChildren(...stevi.problems.slice().reverse().map((p) =>
    el('li', { 'data-key': p.key },
      el('time', {}, p.time.toLocaleTimeString()), ' ', p.message,
      p.count > 1 ? el('span', { class: 'count' }, ` ×${p.count}`) : null)));
}
