// How fresh what the page shows of one device is. The device streams its state every cycle
// (thinned to the display rate), so a gap in the samples is news: the device server, the
// supervisor or the network is down, or the controller's clock is held. The page then says
// so (a stale badge, the 3D view greyed) instead of showing the last picture as if live; and
// when samples come back it says for how long they were missing and whether the device
// restarted meanwhile (its controller clock began again) or only the link broke.
import { clock, duration, readable } from './words.js';

export const STALE_AFTER_MS = 2000;
const CHECK_MS = 250;
const NEW_CONTROLLER_MS = 1000;   // a controller's start moved later by this: another one

export class Freshness {
  constructor() {
    this.lastAt = 0;            // page clock (ms) of the newest sample
    this.lastTime = null;       // its controller time (s) and cycle number
    this.lastSequence = null;
    this.lastStartedMs = null;  // when its controller started (wall clock, ms)
    this.staleSince = null;     // page clock (ms) of the newest sample before the gap
    this.why = '';              // what the backend said of the stream, while it fails
    this.listeners = [];
    this.timer = setInterval(() => this.check(), CHECK_MS);
  }

  // listener({stale, since, why}) when the data goes stale, and ({stale: false, back}) with
  // the sentence about the gap when it is fresh again.
  onChange(listener) { this.listeners.push(listener); }

  get stale() { return this.staleSince !== null; }

  // Age of the newest sample in ms (Infinity before the first).
  age(now = performance.now()) { return this.lastAt ? now - this.lastAt : Infinity; }

  // `wallMs`: when the sample's cycle began (its wall-clock stamp, ms since the epoch).
  sample(sample, wallMs) {
    const now = performance.now();
    const time = Number(sample.controllerTime);
    const sequence = Number(sample.sequence);
    // When its controller started, by the wall clock: constant while one controller runs in
    // real time, earlier and earlier on a clock faster than real time, later for a new one.
    // A new one may have run longer than the old before the page sees it again: its clock
    // and cycle count alone need not have begun again by then.
    const startedMs = wallMs - time * 1000;
    if (this.stale) {
      const missing = now - this.staleSince;
      const restarted = this.lastTime !== null && (time < this.lastTime
        || sequence < this.lastSequence || startedMs > this.lastStartedMs + NEW_CONTROLLER_MS);
      const back = `Live again at ${clock(Date.now())} after ${duration(missing)} without state`
        + (restarted ? ': the device restarted (its controller clock began again).'
          : ': the same controller ran on (the link to it was broken).');
      this.staleSince = null;
      this.why = '';
      this.emit({ stale: false, back, restarted });
    }
    [this.lastAt, this.lastTime, this.lastSequence] = [now, time, sequence];
    this.lastStartedMs = startedMs;
  }

  // The backend's word that the state stream failed (google.rpc.Status).
  failed(status) {
    this.why = readable(status.message);
    this.goStale(performance.now());
  }

  // The page's own link to the supervisor closed: nothing of any device is live.
  linkDown() {
    this.why = 'the connection to the supervisor is down';
    this.goStale(performance.now());
  }

  check() {
    if (!this.stale && this.lastAt && this.age() > STALE_AFTER_MS) this.goStale(this.lastAt);
  }

  goStale(since) {
    if (this.stale) return;
    this.staleSince = this.lastAt || since;
    this.emit({ stale: true, since: this.staleSince, why: this.why });
  }

  // A sentence for the badge's title and the greyed view.
  describe(now = performance.now()) {
    if (!this.lastAt) return 'no live state yet';
    if (!this.stale) return `live: newest state ${duration(this.age(now))} old`;
    const wall = Date.now() - (now - this.staleSince);
    return `stale: no live state since ${clock(wall)} (${duration(now - this.staleSince)})`
      + (this.why ? `: ${this.why}` : '');
  }

  emit(change) { for (const listener of this.listeners) listener(change); }
}
