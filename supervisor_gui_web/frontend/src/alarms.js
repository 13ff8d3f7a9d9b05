// Alarms: each device's alarms from its event stream, newest first, with who acknowledged
// them, and the device's questions (clientAlarmRSVP / clientEventRSVP) with their answers.
//
// An acknowledgement is the device's (EventService.AcknowledgeAlarm): it records it in its audit
// log and tells every client with an AlarmAcknowledged event naming who, which this list shows
// (a page opened later sees them in the replayed history). A question is answered from the page that holds the lock (its session
// is the one the device asks); everyone sees it and how it was answered.
import { clock, severityWord } from './words.js';

const $ = (id) => document.getElementById(id);
const ACKNOWLEDGE = 'landscape.v1.EventService/AcknowledgeAlarm';
const KEPT = 500;
const SEVERITY = { ALARM_SEVERITY_INFO: 1, ALARM_SEVERITY_WARNING: 2, ALARM_SEVERITY_ERROR: 3, ALARM_SEVERITY_CRITICAL: 4 };

// An event's key: its sequence and time (a restarted device numbers from 1 again).
const keyOf = (event) => `${event.sequence}@${event.time}`;

// Who acknowledged, as the device names them: the person a program acted for, with the
// program and the authenticated caller when they say more (tokens off: the caller's address).
function acknowledger({ by, client, onBehalfOf }) {
  if (!onBehalfOf || onBehalfOf === by) return by;
  return `${onBehalfOf} (${[client, by].filter(Boolean).join(', ')})`;
}

export class AlarmBook {
  constructor(ctx) {
    this.ctx = ctx;
    this.entries = [];        // newest first: {key, time, kind: 'alarm'|'question', ...}
    this.byKey = new Map();
    this.acks = new Map();    // key -> {who, at (ms)}
    this.questions = new Map();   // rsvpId -> entry
  }

  // Alarms not acknowledged, information excepted.
  get unacknowledged() {
    return this.entries.filter((e) => e.kind === 'alarm' && e.rank > 1 && !this.acks.has(e.key)).length;
  }

  add(entry) {
    if (this.byKey.has(entry.key)) return;
    this.byKey.set(entry.key, entry);
    this.entries.unshift(entry);
    if (this.entries.length > KEPT) this.byKey.delete(this.entries.pop().key);
    this.ctx.changed('alarms');
  }

  // A landscape.v1 Event (JSON).
  event(event) {
    const time = Date.parse(event.time);
    if (event.alarm) {
      const a = event.alarm;
      this.add({ key: keyOf(event), kind: 'alarm', time, sequence: event.sequence, rank: SEVERITY[a.severity] || 0,
        severity: severityWord(a.severity), code: a.code, message: a.message, commandId: a.commandId });
    } else if (event.rsvpRequest) {
      const r = event.rsvpRequest;
      const entry = { key: keyOf(event), kind: 'question', time, sequence: event.sequence, rank: r.alarm ? 3 : 1,
        severity: r.alarm ? 'question (alarm)' : 'question', code: r.eventId, message: r.data.join(' '),
        request: r, answer: null, answered: '' };
      if (this.pending?.rsvpId === r.rsvpId) entry.answer = this.pending.settle;   // asked first
      this.questions.set(r.rsvpId, entry);
      this.add(entry);
    } else if (event.alarmAcknowledged) {
      const a = event.alarmAcknowledged;
      const entry = this.entries.find((e) => e.kind === 'alarm' && e.sequence === a.alarmSequence);
      if (!entry) return;   // an alarm older than the page's list
      this.acks.set(entry.key, { who: acknowledger(a), at: time });
      this.ctx.changed('alarms');
    } else if (event.rsvpAnswer) {
      const entry = this.questions.get(event.rsvpAnswer.rsvpId);
      if (!entry) return;
      const a = event.rsvpAnswer;
      entry.answered = a.timedOut ? `nobody answered: the device took “${a.choice}”` : `answered “${a.choice}”`;
      entry.answer = null;
      this.ctx.changed('alarms');
    }
  }

  // The device asks this page's session (it holds the lock): answer(choice, data) replies.
  asked(request, answer) {
    const entry = this.questions.get(request.rsvpId);
    const settle = (choice, data) => { answer(choice, data); if (entry) entry.answer = null; this.ctx.changed('alarms'); };
    if (entry && !entry.answered) entry.answer = settle;
    this.pending = { rsvpId: request.rsvpId, settle };
    this.ctx.changed('alarms');
  }

  // Each alarm to the device; its AlarmAcknowledged event marks it, on every page.
  acknowledge(keys) {
    return Promise.all(keys.map((key) => this.byKey.get(key))
      .filter((entry) => entry?.kind === 'alarm')
      .map((entry) => this.ctx.command(ACKNOWLEDGE, { sequence: entry.sequence })));
  }
}

// The list of the selected device's alarms and questions.
export class AlarmPanel {
  constructor(selection) {
    this.selection = selection;
    $('btn-ack-all').addEventListener('click', () => {
      const book = selection.device.alarms;
      book.acknowledge(book.entries.filter((e) => e.kind === 'alarm' && !book.acks.has(e.key)).map((e) => e.key));
    });
    selection.on((what, device) => {
      if (device === selection.device && (what === 'alarms' || what === 'switch')) this.show();
    });
  }

  show() {
    const book = this.selection.device.alarms;
    const list = $('alarms');
    const items = book.entries.map((entry) => this.item(book, entry));
    list.replaceChildren(...items);
    $('alarms-empty').hidden = items.length > 0;
    $('alarm-count').textContent = `${book.unacknowledged} to acknowledge`;
    $('btn-ack-all').disabled = book.unacknowledged === 0 && !book.entries.some((e) => e.kind === 'alarm' && !book.acks.has(e.key));
  }

  item(book, entry) {
    const li = document.createElement('li');
    li.className = `alarm rank-${entry.rank}`;
    li.dataset.key = entry.key;
    const head = document.createElement('span');
    head.className = 'alarm-head';
    head.textContent = `${clock(entry.time)} #${entry.sequence} ${entry.severity} ${entry.code}`;
    const text = document.createElement('span');
    text.className = 'alarm-text';
    text.textContent = entry.message;
    li.append(head, text);
    if (entry.kind === 'question') {
      li.append(this.question(entry));
      return li;
    }
    const ack = book.acks.get(entry.key);
    if (ack) {
      const by = document.createElement('span');
      by.className = 'acked';
      by.textContent = `acknowledged by ${ack.who} at ${clock(ack.at)}`;
      li.append(by);
    } else {
      const button = document.createElement('button');
      button.textContent = 'Acknowledge';
      button.dataset.role = 'operator';
      button.setAttribute('aria-label', `acknowledge alarm ${entry.sequence}: ${entry.message}`);
      button.addEventListener('click', () => book.acknowledge([entry.key]));
      li.append(button);
    }
    return li;
  }

  question(entry) {
    const box = document.createElement('span');
    box.className = 'alarm-answer';
    if (entry.answered) {
      box.textContent = entry.answered;
    } else if (entry.answer) {
      for (const choice of entry.request.choices) {
        const button = document.createElement('button');
        button.textContent = choice;
        button.dataset.choice = choice;
        button.addEventListener('click', () => entry.answer(choice, entry.request.data));
        box.append(button);
      }
    } else {
      box.textContent = `asked of the lock holder: ${entry.request.choices.join(' / ')}`;
    }
    return box;
  }
}
