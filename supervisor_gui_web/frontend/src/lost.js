// The banner that says this page lost its session or its lock, and why, with one button to
// take the lock back. Nothing here takes it back by itself.
//
// Why, in the device's words: the session's end status as the device sent it ("your session
// ended: no keep-alive for 2 s"), and the device's LOCK_HOLDER_LOST alarm. The alarm is this
// page's when it is newer than the page's Lock and comes while the page holds the lock or has
// just lost it (the lock is one: no one else can hold it meanwhile); it also says why when
// gRPC's asyncio client garbled the
// session's status (a keep-alive written after a stall can replace the device's status with
// "Internal error from Core": grpc/grpc#36066).
const $ = (id) => document.getElementById(id);
const LOCK_HOLDER_LOST = 101;   // server/alarms.py

export class LostNotice {
  constructor(log) {
    this.log = log;
    this.what = '';             // what was lost, and the status that said so
    this.deviceSays = '';       // the device's alarm about it
    this.watching = false;      // the lock is or was just ours: its alarm is about us
    this.after = Infinity;      // the newest event sequence when the page took the lock
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
    this.lost(`${status.message}.`, heldLock);
  }

  connectionLost(code) {
    this.lost(`The connection to the supervisor was lost (WebSocket closed, code ${code}): the `
      + 'supervisor ends this page\'s session.', true);
  }

  lockTakenAway(reason) {
    this.lost(`The lock was taken away${reason ? `: ${reason}` : ''}.`, true);
  }

  lost(what, lockToo) {
    this.what = what.charAt(0).toUpperCase() + what.slice(1);
    this.lockToo = lockToo;
    this.show();
    this.log.addRefused(`lost: ${this.text()}`);
  }

  text() {
    const device = this.deviceSays ? ` The device: ${this.deviceSays}.`
      : this.lockToo ? ' The device stops the arm, powers down and releases the lock.' : '';
    return this.what + device;
  }

  show() {
    $('lost-text').textContent = this.text();
    $('lost').hidden = false;
  }

  hide() {
    this.what = '';
    $('lost').hidden = true;
  }
}
