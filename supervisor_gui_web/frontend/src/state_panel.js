// The state at a glance: state machine position, lock holder, power, motion, tag, tool, speed
// settings, units, cycle health; the joints against their ranges. Values are shown in the
// device's units (GetUnits); the samples come in the stream's units (StreamStarted / sample).
import { fmt, fromSI, symbol, toSI } from './units.js';

const $ = (id) => document.getElementById(id);
// Only a text that changed is written: every write costs the page a repaint.
function put(element, text) {
  if (element.textContent !== text) element.textContent = text;
}
const TEXT_HZ = 8;
const short = (name, prefix) => (name || '').replace(prefix, '').toLowerCase() || '–';

export class StatePanel {
  constructor(ctx) {
    this.ctx = ctx;
    this.limits = [];          // [{name, lower, upper}] in radians, from the URDF
    this.received = [];        // page clock (ms) of recent samples, for the rate received
    this.shownAt = 0;
  }

  setLimits(limits) {
    this.limits = limits;
    const box = $('joints');
    box.replaceChildren();
    for (const limit of limits) {
      const row = document.createElement('div');
      row.className = 'joint';
      row.innerHTML = `<span class="jname">${limit.name}</span><span class="bar"><span class="mark"></span></span><span class="jvalue"></span>`;
      row.dataset.joint = limit.name;
      box.append(row);
    }
  }

  // Called for every StateSample; `age` is ms from the cycle that produced it (or NaN).
  // The text is written at most TEXT_HZ times a second (a state change or an e-stop at once):
  // faster is unreadable, and each write costs a repaint the next sample would wait behind.
  sample(sample, age) {
    const now = performance.now();
    this.received.push(now);
    while (this.received[0] < now - 2000) this.received.shift();
    const urgent = sample.deviceState !== this.shownState || sample.estop !== this.shownEstop;
    if (!urgent && now - this.shownAt < 1000 / TEXT_HZ) return;
    [this.shownAt, this.shownState, this.shownEstop] = [now, sample.deviceState, sample.estop];
    const units = this.ctx.model.units;
    const sampleUnits = sample.units || units;
    const angle = (v) => fromSI(toSI(v, 'angular', sampleUnits), 'angular', units);
    const length = (v) => fromSI(toSI(v, 'linear', sampleUnits), 'linear', units);

    put($('st-state'), short(sample.deviceState, 'DEVICE_STATE_'));
    put($('st-power'), sample.controlMode || '–');
    put($('st-motion'), sample.motionControlState || '–');
    put($('st-estop'), sample.estop ? 'PRESSED' : 'released');
    $('st-estop').className = sample.estop ? 'alert' : '';
    put($('st-command'), sample.commandId || '–');
    put($('st-tag'), `${sample.pointName || '–'} / ${sample.tagName || '–'}`);
    const p = sample.toolPose || {};
    const frame = short(this.ctx.model.started?.frame, 'REFERENCE_FRAME_').replace('_cartesian_frame', '');
    put($('st-pose'), `${frame}: ${['x', 'y', 'z'].map((k) => fmt(length(p[k] || 0))).join(' ')} ${symbol(units.linear)}, `
      + `${['roll', 'pitch', 'yaw'].map((k) => fmt(angle(p[k] || 0))).join(' ')} ${symbol(units.angular)}`);
    const rate = this.received.length / 2;
    put($('st-cycle'), sample.sequence && sample.sequence !== '0'
      ? `#${sample.sequence}, t ${fmt(sample.controllerTime, 2)} s, skipped ${sample.skipped}, age ${fmt(age, 1)} ms, ${fmt(rate, 0)}/s`
      : `no cycle number, ${fmt(rate, 0)}/s`);
    return this.joints(sample, sampleUnits, units);
  }

  joints(sample, sampleUnits, units) {
    const joints = sample.jointPositions || [];
    document.querySelectorAll('#joints .joint').forEach((row, i) => {
      const limit = this.limits[i];
      const q = toSI(joints[i] ?? 0, 'angular', sampleUnits);
      const share = (q - limit.lower) / (limit.upper - limit.lower);
      row.querySelector('.mark').style.left = `${Math.min(100, Math.max(0, share * 100))}%`;
      row.classList.toggle('near-limit', share < 0.03 || share > 0.97);
      put(row.querySelector('.jvalue'), `${fmt(fromSI(q, 'angular', units))} ${symbol(units.angular)}`
        + ` [${fmt(fromSI(limit.lower, 'angular', units), 2)}, ${fmt(fromSI(limit.upper, 'angular', units), 2)}]`);
    });
  }

  // The status reads (GetDeviceState, GetVelocities, ...) after any of them changed.
  status() {
    const s = this.ctx.model.status;
    const d = s.GetDeviceState;
    if (d?.refused) {
      put($('st-lock'), `unknown (${d.refused.message})`);
    } else if (d) {
      put($('st-lock'), d.locked ? d.lockHolder : 'nobody');
      put($('st-manual'), d.manualControl || '–');
      put($('st-error'), d.error || '–');
      if (!this.ctx.model.sample) put($('st-state'), short(d.state, 'DEVICE_STATE_'));
    }
    const ee = s.GetEndEffectorState;
    put($('st-tool'), ee ? (ee.refused ? `not available (${ee.refused.message})` : `${ee.currentEe || 'none'} ${ee.eeState}`) : '–');
    const v = s.GetVelocities;
    const a = s.GetAccelerations;
    if (v && a && !v.refused && !a.refused) put($('st-speed'), `${fmt(v.percentVelocity, 0)} % / ${fmt(a.percentAccel, 0)} %`);
    const u = this.ctx.model.units;
    put($('st-units'), `${symbol(u.linear)}, ${symbol(u.angular)}`);
    document.querySelectorAll('.unit-angle').forEach((e) => { e.textContent = symbol(u.angular); });
  }
}
