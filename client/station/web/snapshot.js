// The snapshot overlay (.snapshot-overlay): a rig's snapshot PNG over the page with a download
// link; closed by its button, a click beside the image or Escape.

import { el } from './util.js';

export function showSnapshot(rigName, kind, blob) {
  const old = document.querySelector('.snapshot-overlay');
  if (old) old.dispatchEvent(new Event('close'));
  const url = URL.createObjectURL(blob);
  const stamp = new Date().toISOString().replace(/[:.]/g, '-');
  const close = el('button', { class: 'snapshot-close', type: 'button' }, 'close');
  const overlay = el('div', { class: 'snapshot-overlay', 'data-rig': rigName, 'data-kind': kind },
    el('div', { class: 'snapshot-bar' },
      el('span', {}, `${rigName} ${kind} snapshot`), el('span', { class: 'spacer' }),
      el('a', { class: 'snapshot-download', href: url, download: `${rigName}-${kind}-${stamp}.png` }, 'download'),
      close),
    el('img', { class: 'snapshot-image', src: url, alt: `${rigName} ${kind} snapshot` }));
  const done = () => { overlay.remove(); URL.revokeObjectURL(url); };
  overlay.addEventListener('close', done);
  close.addEventListener('click', done);
  overlay.addEventListener('click', (ev) => { if (ev.target === overlay) done(); });
  document.body.append(overlay);
}

// Escape closes the overlay.
export function closeSnapshotOnEscape() {
  document.addEventListener('keydown', (ev) => {
    if (ev.key !== 'Escape') return;
    const o = document.querySelector('.snapshot-overlay');
    if (o) o.dispatchEvent(new Event('close'));
  });
}
