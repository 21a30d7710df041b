// The video boxes of a rig: the annotated image (the server draws the tracks' boxes on it) and
// the disparity image, each a foxglove.CompressedImage shown in an <img> (data-seq, data-stamp).

import { el } from './util.js';
import { addProblem } from './problems.js';

const IMAGE_TYPES = { jpeg: 'image/jpeg', jpg: 'image/jpeg', png: 'image/png', webp: 'image/webp', avif: 'image/avif' };

export class VideoPanel {
  // `kind`: 'annotated' or 'disparity'.
  constructor(rigName, kind, label) {
    this.url = null;  // the object URL shown
    this.img = el('img', { class: 'video', 'data-kind': kind, alt: `${rigName} ${label}`, 'data-seq': '0' });
    const caption = el('figcaption', {}, label);
    this.placeholder = el('div', { class: 'video-placeholder' }, `no ${label} image yet`);
    this.img.addEventListener('load', () => {
      caption.textContent = `${label} · ${this.img.naturalWidth}×${this.img.naturalHeight}`;
    });
    this.img.addEventListener('error', () => {
      if (this.img.getAttribute('src')) addProblem(`image:${rigName}:${kind}`, `${rigName}: cannot show the ${label} image`);
    });
    this.box = el('figure', { class: 'box video-box' }, this.img, this.placeholder, caption);
  }

  // Shows a foxglove.CompressedImage, the rig's `count`th of this kind.
  show(msg, count) {
    const format = (msg.format || 'jpeg').toLowerCase();
    const type = IMAGE_TYPES[format] || 'image/jpeg';
    const url = URL.createObjectURL(new Blob([msg.data], { type }));
    const previous = this.url;
    this.url = url;
    this.img.src = url;
    if (previous) URL.revokeObjectURL(previous);  // the shown image stays until the new one loads
    const ts = msg.timestamp || { seconds: 0, nanos: 0 };
    this.img.dataset.seq = String(count);
    this.img.dataset.stamp = `${ts.seconds}.${String(ts.nanos).padStart(9, '0')}`;
    this.placeholder.hidden = true;
  }
}
