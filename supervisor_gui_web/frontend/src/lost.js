// The banner that says this page lost its session or its lock on a device, and why, with one
// button to take the lock back; and, beside it, what happened while the device's state was
// missing, once it is back. Nothing here takes the lock back by itself.
//
// Why, in the device's words: the session's end status as the device sent it ("your session
// ended: no keep-alive for 2 s"), and the device's LOCK_HOLDER_LOST alarm. The alarm is this
// page's when it is newer than the page's Lock and comes while the page holds the lock or has
// just lost it (the lock is one: no one else can hold it meanwhile); it also says why when
// gRPC's asyncio client garbled the session's status (a keep-alive written after a stall can
// replace the device's status with "Internal error from Core": grpc/grpc#36066).
import { readable } from './words.js';

const LOCK_HOLDER_LOST = 101;   // server/alarms.py

function element(tag, className, text = '') {
  const made = document.createElement(tag);
  made.className = className;
  made.textContent = text;
  return made;
}

export class LostNotice {
  // device: its name; log: the event log; takeBack(): a session if needed, then the lock.
  constructor(device, log, takeBack) {
    this.device = device;
    this.log = log;
    this.what = '';             // what was lost, and the status that said so
    this.deviceSays = '';       // the device's alarm about it
    this.watching = false;      // the lock is or was just ours: its alarm is about us
    this.after = Infinity;      // the newest event sequence when the page took the lock
    this.box = element('div', 'banner lost');
    this.box.dataset.device = device;
    this.box.dataset.testid = `lost-${device}`;
    this.box.setAttribute('role', 'alert');
    this.box.hidden = true;
    this.text = element('span', 'lost-text');
    this.button = element('button', 'take-back', 'Take the lock back');
    this.button.dataset.role = 'operator';
    this.button.dataset.testid = `take-back-${device}`;
    this.button.addEventListener('click', takeBack);
    // Only "it is back" to say (no loss of ours): a note the person dismisses.
    this.dismiss = element('button', 'dismiss', '×');
    this.dismiss.setAttribute('aria-label', `dismiss the note about ${device}`);
    this.dismiss.addEventListener('click', () => this.hide());
    this.box.append(element('strong', 'banner-device', `${device}: `), this.text, this.button, this.dismiss);
    document.getElementById('banners').append(this.box);
  }

  // The page holds the lock (again), taken after event `sequence`: a new loss starts afresh.
  lockTaken(sequence) {
    this.watching = true;
    this.after = sequence;
    this.deviceSays = '';
    this.hide();
  }

  // A landscape.v1 Event (JSON) from the event stream.
  event(event) {
    const alarm = event.alarm;
    if (alarm?.code !== LOCK_HOLDER_LOST || !this.watching || this.deviceSays
        || Number(event.sequence) <= this.after) return;
    this.deviceSays = alarm.message;
    if (this.what) this.show();
  }

  // The lock was given back on purpose: later alarms are someone else's.
  released() {
    this.watching = false;
  }

  sessionEnded(status, heldLock) {
    this.lost(`${readable(status.message)}.`, heldLock);
  }

  connectionLost(code) {
    this.lost(`The connection to the supervisor was lost (WebSocket closed, code ${code}): the `
      + 'supervisor ends this page\'s session.', true);
  }

  lockTakenAway(reason) {
    this.lost(`The lock was taken away${reason ? `: ${reason}` : ''}.`, true);
  }

  // The device's state is live again after a gap; `back` says how long and what happened.
  cameBack(back) {
    this.back = back;
    this.show();
  }

  lost(what, lockToo) {
    this.what = what.charAt(0).toUpperCase() + what.slice(1);
    this.lockToo = lockToo;
    this.show();
    this.log.addRefused(`${this.device} lost: ${this.sentence()}`);
  }

  sentence() {
    const device = this.deviceSays ? ` The device: ${readable(this.deviceSays)}.`
      : this.lockToo ? ' The device stops the arm, powers down and releases the lock.' : '';
    if (!this.what) return this.back;
    return this.what + device + (this.back ? ` ${this.back}` : '');
  }

  show() {
    this.text.textContent = this.sentence();
    this.box.classList.toggle('info', !this.what);
    this.button.hidden = !this.what;
    this.dismiss.hidden = Boolean(this.what);
    this.box.hidden = false;
  }

  hide() {
    this.what = '';
    this.back = '';
    this.box.hidden = true;
  }
}
