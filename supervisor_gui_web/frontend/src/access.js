// What the person may press: a control their role does not allow is disabled with the reason
// (the backend refuses it anyway), and so is one that needs the lock (data-needs="lock") or a
// session (data-needs="session") on the selected device while this page has none. What is
// allowed in which state is the server's call: a button enabled here may still be refused, and
// the refusal is shown as the server gave it. Controls made later (jog buttons, I/O bits,
// alarm buttons) are gated as soon as they are in the page.
const $ = (id) => document.getElementById(id);
export const RANK = { viewer: 1, operator: 2, admin: 3 };
const MAY = {
  viewer: 'a viewer watches and may press the e-stop',
  operator: 'an operator commands',
  admin: 'an admin also works the operator panel and resets',
};

export class Access {
  constructor(selection, person) {
    this.selection = selection;
    this.person = person;
    selection.on((what, device) => {
      if (device === selection.device && ['switch', 'session', 'lock', 'status'].includes(what)) this.apply();
    });
    let queued = false;
    new MutationObserver((records) => {
      const added = records.some((r) => [...r.addedNodes].some((node) => node.nodeType === Node.ELEMENT_NODE));
      if (queued || !added) return;
      queued = true;
      queueMicrotask(() => { queued = false; this.apply(); });
    }).observe(document.body, { childList: true, subtree: true });
    this.apply();
  }

  get rank() { return RANK[this.person.role] || 0; }

  apply() {
    const ctx = this.selection.ctx;
    const rank = this.rank;
    const asWho = `you are signed in as ${this.person.role} (${MAY[this.person.role]})`;
    const status = ctx.model.status.GetDeviceState;
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
      set(element, blocked, !blocked ? '' : rank < RANK.operator || needs === 'lock' ? reason : 'open a session first');
    }
    for (const element of document.querySelectorAll('[data-role]')) {
      const needed = element.dataset.role;
      const blocked = rank < RANK[needed];
      set(element, blocked, blocked ? `${element.textContent} needs the ${needed} role; ${asWho}` : element.dataset.title || '');
    }
    if (rank >= RANK.operator) $('btn-session').disabled = Boolean(ctx.session);
    const role = $('role');
    role.textContent = ctx.holdsLock ? `${ctx.device}: commanding (${ctx.session?.sessionId})`
      : rank < RANK.operator ? 'watching only (viewer)' : `${ctx.device}: ${reason}`;
    role.title = reason;
    role.className = `pill ${ctx.holdsLock ? 'owner' : 'watcher'}`;
  }
}

// Only what changed is written: a write re-runs style and layout.
function set(element, disabled, title) {
  if (element.disabled !== disabled) element.disabled = disabled;
  if (element.title !== title) element.title = title;
}
