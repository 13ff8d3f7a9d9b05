// A refused command, shown where it covers nothing the operator watches: a note at the
// bottom of the window (the state and the e-stop are at the top), which the next refusal
// replaces, × or Escape dismisses, and which goes by itself after a while. The log keeps
// every refusal.
import { explain } from './words.js';

const $ = (id) => document.getElementById(id);
const SHOWN_MS = 12000;

export class Refusals {
  constructor(log) {
    this.log = log;
    this.box = $('refusal');
    $('btn-refusal-close').addEventListener('click', () => this.hide());
    document.addEventListener('keydown', (event) => {
      if (event.key === 'Escape' && !this.box.hidden && !document.querySelector('dialog[open]')) this.hide();
    });
  }

  // `what` ("SetSpeed", "Jog") of `device` was refused with google.rpc.Status `status`.
  show(device, what, status) {
    const { text, codes } = explain(status);
    $('refusal-text').textContent = `${device}: ${what} refused: ${text}`;
    $('refusal-codes').textContent = codes;
    this.box.hidden = false;
    clearTimeout(this.timer);
    this.timer = setTimeout(() => this.hide(), SHOWN_MS);
    this.log.addRefused(`${device} ${what}: ${text}`, codes);
  }

  hide() {
    clearTimeout(this.timer);
    this.box.hidden = true;
  }
}
