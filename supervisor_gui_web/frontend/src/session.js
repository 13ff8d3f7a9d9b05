// The page's session and lock on one device: open, lock, release, take back; and the watch
// that a lost session or lock is never silent and never taken back silently: the page's
// socket closing, the device ending the session (with its reason, a device server that went
// away included), or the lock going away show the device's banner with the reason and one
// button to take the lock back.
import { LostNotice } from './lost.js';

const CONNECT = 'landscape.v1.SessionService/Connect';
const UNAVAILABLE = 14;

export class DeviceSession {
  // onRsvp(request, answer): the device asks this page's session a question.
  constructor(ctx, onRsvp) {
    this.ctx = ctx;
    this.onRsvp = onRsvp;
    this.notice = new LostNotice(ctx.device, ctx.log, () => this.takeBack());
    this.lockSeen = false;
    ctx.link.onConnection((up, event) => {
      if (!up && (ctx.session || ctx.holdsLock)) this.notice.connectionLost(event?.code);
    });
    ctx.onChange((what) => { if (what === 'status') this.checkLock(); });
  }

  // Opens the page's session; resolves true once the device opened it.
  open() {
    const ctx = this.ctx;
    if (ctx.session) return Promise.resolve(Boolean(ctx.session.sessionId));
    return new Promise((resolve) => {
      const stream = ctx.link.open(ctx.device, CONNECT, (frame) => {
        if (frame.reply?.opened) {
          ctx.session = { stream, sessionId: frame.reply.opened.sessionId };
          ctx.changed('session');
          resolve(true);
        } else if (frame.reply?.rsvpRequest) {
          const request = frame.reply.rsvpRequest;
          this.onRsvp(ctx.device, request, (choice, data) => stream.send({ rsvpAnswer: { rsvpId: request.rsvpId, choice, data } }));
        }
        if (frame.status) this.ended(frame.status, resolve);
      });
      ctx.session = { stream, sessionId: '' };
      stream.send({ hello: {} });
      ctx.changed('session');
    });
  }

  // The session stream ended with google.rpc.Status `status`.
  ended(status, resolve) {
    const ctx = this.ctx;
    const wasOpen = Boolean(ctx.session?.sessionId);
    const heldLock = ctx.holdsLock;
    ctx.session = null;
    this.setLock(false);
    if (status.code && !wasOpen) ctx.refused('session', status);
    // A closed WebSocket says so itself (connectionLost); any other end is the device's word,
    // a device server that went away (UNAVAILABLE) included.
    else if (status.code && !(status.code === UNAVAILABLE && !ctx.link.up)) this.notice.sessionEnded(status, heldLock);
    resolve(false);
  }

  close() {
    this.ctx.session?.stream.cancel();
  }

  async lock() {
    if (!await this.ctx.command('Lock')) return false;
    this.locked();
    return true;
  }

  // The lock is this page's now (its Lock, or a hand-over to it).
  locked() {
    this.notice.lockTaken(this.ctx.lastSequence);
    this.setLock(true);
  }

  async release() {
    if (!await this.lettingGo(() => this.ctx.command('Release'))) return false;
    this.notice.released();
    this.setLock(false);
    return true;
  }

  // While this page lets the lock go (Release, a hand-over), a read showing it gone is that,
  // not a loss: the read may come before the call's reply or the "given" note.
  async lettingGo(call) {
    this.lettingGoNow = true;
    try {
      return await call();
    } finally {
      this.lettingGoNow = false;
    }
  }

  // The lock was handed to someone else on this page's word: not a loss.
  handedOver() {
    this.notice.released();
    this.setLock(false);
  }

  // One click: a session if the page has none, then the lock.
  async takeBack() {
    if (await this.open()) await this.lock();
  }

  // A landscape.v1 Event of this device (the event stream).
  event(event) {
    this.notice.event(event);
  }

  setLock(holds) {
    this.ctx.holdsLock = holds;
    this.lockSeen = false;
    this.ctx.changed('lock');
  }

  // The lock is ours from Lock's reply (or a hand-over) until GetDeviceState, having shown it
  // ours, shows it unlocked (released, or the device's disconnect handler) or held by someone
  // else; a read older than the lock (unlocked, or the previous holder's) may still arrive
  // after the reply, and is not taken as losing it.
  checkLock() {
    const ctx = this.ctx;
    const status = ctx.model.status.GetDeviceState;
    if (!ctx.holdsLock || this.lettingGoNow || !status || status.refused) return;
    if (status.locked && status.lockHolder === ctx.person.name) this.lockSeen = true;
    if (this.lockSeen && (!status.locked || status.lockHolder !== ctx.person.name)) {
      ctx.holdsLock = false;
      this.notice.lockTakenAway(ctx.lastStateReason);
      ctx.changed('lock');
    }
  }
}
