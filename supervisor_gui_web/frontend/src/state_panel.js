// The selected device's state in detail: state machine position, lock holder, power, motion,
// tag, tool, speed settings, units, cycle health; the joints against their ranges. Values are
// shown in the device's units (GetUnits); the samples come in meters and radians.
import { fmt, fromSI, symbol } from './units.js';
import { frameWord, manualWord, motionWord, readable, stateWord } from './words.js';

const $ = (id) => document.getElementById(id);
// Only a text that changed is written: every write costs the page a repaint.
export function put(element, text) {
  if (element.textContent !== text) element.textContent = text;
}
const TEXT_HZ = 8;

export class StatePanel {
  constructor(selection) {
    this.selection = selection;
    this.received = new Map();   // device -> page clock (ms) of recent samples, for the rate
    this.shownAt = 0;
    selection.on((what, device) => {
      if (what === 'sample') this.count(device);
      if (device !== selection.device) return;
      if (what === 'sample') this.sample();
      else if (what === 'switch') { this.rows(); this.shownState = null; this.sample(); this.status(); }
      else if (what === 'robot') this.rows();
      else if (what === 'status') this.status();
      else if (what === 'note') put($('st-note'), device.note);
    });
  }

  count(device) {
    const now = performance.now();
    const times = this.received.get(device) || [];
    times.push(now);
    while (times[0] < now - 2000) times.shift();
    this.received.set(device, times);
  }

  // One row per joint, from the URDF's limits.
  rows() {
    const limits = this.selection.device.limits || [];
    const box = $('joints');
    box.replaceChildren(...limits.map((limit) => {
      const row = document.createElement('div');
      row.className = 'joint';
      row.dataset.joint = limit.name;
      row.innerHTML = '<span class="jname"></span><span class="bar"><span class="mark"></span></span><span class="jvalue"></span>';
      row.querySelector('.jname').textContent = limit.name.replace('joint_', 'J');
      return row;
    }));
    put($('st-note'), this.selection.device.note);
  }

  // The newest sample. The text is written at most TEXT_HZ times a second (a state change or
  // an e-stop at once): faster is unreadable, and each write costs a repaint the next sample
  // would wait behind.
  sample() {
    const device = this.selection.device;
    const sample = device.ctx.model.sample;
    if (!sample) return;
    const now = performance.now();
    const urgent = sample.deviceState !== this.shownState || sample.estop !== this.shownEstop;
    if (!urgent && now - this.shownAt < 1000 / TEXT_HZ) return;
    [this.shownAt, this.shownState, this.shownEstop] = [now, sample.deviceState, sample.estop];
    const units = device.ctx.model.units;
    const angle = (v) => fromSI(v, 'angular', units);
    const length = (v) => fromSI(v, 'linear', units);

    put($('st-state'), stateWord(sample.deviceState));
    put($('st-power'), motionWord(sample.controlMode));
    put($('st-motion'), motionWord(sample.motionControlState));
    put($('st-estop'), sample.estop ? 'PRESSED' : 'released');
    $('st-estop').className = sample.estop ? 'alert' : '';
    put($('st-command'), sample.commandId || '–');
    put($('st-tag'), `${sample.pointName || '–'} / ${sample.tagName || '–'}`);
    const p = sample.toolPose || {};
    put($('st-pose'), `${frameWord(device.ctx.model.started?.frame)}: ${['x', 'y', 'z'].map((k) => fmt(length(p[k] || 0))).join(' ')} ${symbol(units.linear)}, `
      + `${['roll', 'pitch', 'yaw'].map((k) => fmt(angle(p[k] || 0))).join(' ')} ${symbol(units.angular)}`);
    const rate = (this.received.get(device) || []).length / 2;
    put($('st-cycle'), sample.sequence && sample.sequence !== '0'
      ? `#${sample.sequence}, t ${fmt(sample.controllerTime, 2)} s, skipped ${sample.skipped}, age ${fmt(device.age, 1)} ms, ${fmt(rate, 0)}/s`
      : `no cycle number, ${fmt(rate, 0)}/s`);
    this.joints(device, sample, units);
  }

  joints(device, sample, units) {
    const joints = sample.jointPositions || [];
    const limits = device.limits || [];
    document.querySelectorAll('#joints .joint').forEach((row, i) => {
      const limit = limits[i];
      if (!limit) return;
      const q = joints[i] ?? 0;
      const share = (q - limit.lower) / (limit.upper - limit.lower);
      row.querySelector('.mark').style.left = `${Math.min(100, Math.max(0, share * 100))}%`;
      row.classList.toggle('near-limit', share < 0.03 || share > 0.97);
      put(row.querySelector('.jvalue'), `${fmt(fromSI(q, 'angular', units))} ${symbol(units.angular)}`
        + ` [${fmt(fromSI(limit.lower, 'angular', units), 2)}, ${fmt(fromSI(limit.upper, 'angular', units), 2)}]`);
    });
  }

  // The status reads (GetDeviceState, GetVelocities, ...) after any of them changed.
  status() {
    const ctx = this.selection.ctx;
    const s = ctx.model.status;
    const d = s.GetDeviceState;
    if (d?.refused) {
      put($('st-lock'), `unknown (${readable(d.refused.message)})`);
    } else if (d) {
      put($('st-lock'), d.locked ? d.lockHolder : 'nobody');
      put($('st-manual'), manualWord(d.manualControl));
      put($('st-error'), readable(d.error) || '–');
      if (!ctx.model.sample) put($('st-state'), stateWord(d.state));
    }
    const ee = s.GetEndEffectorState;
    put($('st-tool'), ee ? (ee.refused ? `not available (${readable(ee.refused.message)})` : `${ee.currentEe || 'none'} ${ee.eeState}`) : '–');
    const v = s.GetVelocities;
    const a = s.GetAccelerations;
    if (v && a && !v.refused && !a.refused) put($('st-speed'), `${fmt(v.percentVelocity, 0)} % / ${fmt(a.percentAccel, 0)} %`);
    const u = ctx.model.units;
    put($('st-units'), `${symbol(u.linear)}, ${symbol(u.angular)}`);
    document.querySelectorAll('.unit-angle').forEach((e) => { e.textContent = symbol(u.angular); });
  }
}
