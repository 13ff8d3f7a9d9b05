// The control panel: the page's session and lock, power, reset, the operator panel's e-stop,
// speed and units; and what may be pressed: a control the person's role does not allow is
// disabled with the reason (the backend refuses it anyway), and so is one that needs the lock
// while this page does not hold it. What is allowed in which state is the server's call: a
// button enabled here may still be refused, and the refusal is shown as the server gave it.
//
// A lost session or lock is never silent and never taken back silently: the page's socket
// closing, the device ending the session (with its reason), or the lock going away show the
// banner with the reason, the controls disabled, and one button to take the lock back.
import { LostNotice } from './lost.js';

const $ = (id) => document.getElementById(id);
const CONNECT = 'landscape.v1.SessionService/Connect';
const RANK = { viewer: 1, operator: 2, admin: 3 };
const MAY = {
  viewer: 'a viewer watches and may press the e-stop',
  operator: 'an operator commands',
  admin: 'an admin also works the operator panel and resets',
};

export class Controls {
  constructor(ctx, { onRsvp }) {
    this.ctx = ctx;
    this.onRsvp = onRsvp;
    this.notice = new LostNotice(ctx.log);
    const on = (id, handler) => $(id).addEventListener('click', handler);
    on('btn-session', () => this.openSession());
    on('btn-session-close', () => this.ctx.session && this.ctx.session.stream.cancel());
    on('btn-lock', () => this.lock());
    on('btn-release', async () => {
      if (!await ctx.command('Release')) return;
      this.notice.released();
      this.setLock(false);
    });
    on('btn-activate', () => ctx.command('Activate'));
    on('btn-deactivate', () => ctx.command('Deactivate'));
    on('btn-reset', () => ctx.command('Reset'));
    on('btn-estop-press', () => ctx.command('OperatePanel', { action: 'PANEL_ACTION_PRESS_ESTOP' }));
    on('btn-estop-release', () => ctx.command('OperatePanel', { action: 'PANEL_ACTION_RELEASE_ESTOP' }));
    on('btn-speed', () => ctx.command('SetSpeed', { speed: Number($('speed').value), attribute: 'SPEED_TYPE_PERCENT_SPEED' }));
    on('btn-accel', () => ctx.command('SetAcceleration', { accel: Number($('accel').value), attribute: 'ACCEL_TYPE_PERCENT_ACCEL' }));
    on('btn-units', () => ctx.command('SetUnits', { linearUnits: $('units-linear').value, angularUnits: $('units-angular').value }));
    on('btn-take-back', () => this.takeBack());
    ctx.link.onConnection((up, event) => {
      if (!up && (ctx.session || ctx.holdsLock)) this.notice.connectionLost(event?.code);
    });
    ctx.onChange(() => this.updateRole());
    this.updateRole();
  }

  // Opens the page's session; resolves true once the device opened it.
  openSession() {
    const ctx = this.ctx;
    if (ctx.session) return Promise.resolve(Boolean(ctx.session.sessionId));
    return new Promise((resolve) => {
      const stream = ctx.link.open(ctx.device, CONNECT, (frame) => {
        if (frame.reply?.opened) {
          ctx.session = { stream, sessionId: frame.reply.opened.sessionId };
          ctx.changed('session');
          resolve(true);
        } else if (frame.reply?.rsvpRequest) {
          this.onRsvp(frame.reply.rsvpRequest, (choice, data) => stream.send({ rsvpAnswer: { rsvpId: frame.reply.rsvpRequest.rsvpId, choice, data } }));
        }
        if (frame.status) {
          const wasOpen = Boolean(ctx.session?.sessionId);
          const heldLock = ctx.holdsLock;
          ctx.session = null;
          this.setLock(false);
          if (frame.status.code && !wasOpen) ctx.refused('session', frame.status);
          else if (frame.status.code && frame.status.code !== 14) this.notice.sessionEnded(frame.status, heldLock);
          resolve(false);
        }
      });
      ctx.session = { stream, sessionId: '' };
      stream.send({ hello: {} });
      ctx.changed('session');
    });
  }

  async lock() {
    if (!await this.ctx.command('Lock')) return false;
    this.notice.lockTaken(this.ctx.lastSequence);
    this.setLock(true);
    return true;
  }

  // One click: a session if the page has none, then the lock.
  async takeBack() {
    if (await this.openSession()) await this.lock();
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

  updateRole() {
    const ctx = this.ctx;
    const status = ctx.model.status.GetDeviceState;
    // The lock is ours from Lock's reply until GetDeviceState, having shown it locked, shows
    // it unlocked (released, or the device's disconnect handler); a read older than the lock
    // may still arrive after its reply, and is not taken as losing it.
    if (ctx.holdsLock && status?.locked) this.lockSeen = true;
    if (ctx.holdsLock && this.lockSeen && status && (!status.locked || status.lockHolder !== ctx.person.name)) {
      ctx.holdsLock = false;
      this.notice.lockTakenAway(ctx.lastStateReason);
    }
    const rank = RANK[ctx.person.role] || 0;
    const asWho = `you are signed in as ${ctx.person.role} (${MAY[ctx.person.role]})`;
    const holder = status?.locked ? status.lockHolder : '';
    const hasSession = Boolean(ctx.session?.sessionId);
    let reason = '';
    if (rank < RANK.operator) reason = `commanding needs the operator role; ${asWho}`;
    else if (!ctx.holdsLock) {
      reason = holder ? `watching: the lock is held by ${holder}` :
        hasSession ? 'take the lock to command' : 'open a session and take the lock to command';
    }
    for (const element of document.querySelectorAll('[data-needs]')) {
      const needs = element.dataset.needs;
      const blocked = rank < RANK.operator || (needs === 'lock' ? !ctx.holdsLock : !hasSession);
      element.disabled = blocked;
      element.title = !blocked ? '' : rank < RANK.operator || needs === 'lock' ? reason : 'open a session first';
    }
    for (const element of document.querySelectorAll('[data-role]')) {
      const needed = element.dataset.role;
      element.disabled = rank < RANK[needed];
      element.title = element.disabled ? `${element.textContent} needs the ${needed} role; ${asWho}` : '';
    }
    if (rank >= RANK.operator) $('btn-session').disabled = Boolean(ctx.session);
    const role = $('role');
    role.textContent = ctx.holdsLock ? `commanding (${ctx.session?.sessionId})`
      : rank < RANK.operator ? 'watching only (viewer)' : reason;
    role.title = reason;
    role.className = `pill ${ctx.holdsLock ? 'owner' : 'watcher'}`;
  }
}
