// Live plots (uPlot) over a sliding window: joint positions, joint velocities, the tool tip,
// the force sensor and the joints' following error. Each device keeps its own series
// (PlotData), gathered all the time; the plots draw the selected device's.
import uPlot from 'uplot';
import 'uplot/dist/uPlot.min.css';
import { fromSI, symbol, tickText } from './units.js';

const WINDOW_S = 10;
const REDRAW_HZ = 5;
const HEIGHT = 170;   // px, the x axis (seconds) included
const COLORS = ['#c62828', '#2e7d32', '#1565c0', '#ef6c00', '#6a1b9a', '#00838f'];
const JOINTS = ['J1', 'J2', 'J3', 'J4', 'J5', 'J6'];

// What each plot shows: its series, its unit (from the device's units) and the smallest span
// its axis shows (SI), so a still arm's flat line is not drawn as noise.
const PLOTS = {
  joints: { labels: JOINTS, kind: 'angular', unit: (u) => symbol(u.angular), span: 0.01 },
  velocities: { labels: JOINTS, kind: 'angular', unit: (u) => `${symbol(u.angular)}/s`, span: 0.02 },
  tip: { labels: ['x', 'y', 'z'], kind: 'linear', unit: (u) => symbol(u.linear), span: 0.001 },
  force: { labels: ['fx', 'fy', 'fz'], kind: null, unit: () => 'N', span: 1 },
  following: { labels: JOINTS, kind: 'angular', unit: (u) => symbol(u.angular), span: 1e-4 },
};

// One device's series, in SI, gathered from every sample.
export class PlotData {
  constructor() {
    this.series = Object.fromEntries(Object.entries(PLOTS).map(([name, p]) => [name, [[], ...p.labels.map(() => [])]]));
    this.missing = {};   // plot name -> why it has no data
  }

  push(name, t, values) {
    const [x, ...ys] = this.series[name];
    x.push(t);
    ys.forEach((y, i) => y.push(values[i] ?? null));
    while (x.length && x[0] < t - WINDOW_S) { x.shift(); ys.forEach((y) => y.shift()); }
  }

  // A StateSample (JSON) in SI (the backend asks for meters and radians); t in seconds.
  add(sample, t) {
    const measured = sample.jointPositions || [];
    this.push('joints', t, measured);
    this.push('velocities', t, sample.jointVelocities || []);
    const p = sample.toolPose;
    if (p) this.push('tip', t, [p.x, p.y, p.z]);
    const force = (sample.sensors || []).find((s) => s.name === 'force_sensor');
    if (force) this.push('force', t, force.values.slice(0, 3));
    this.missing.force = force ? '' : 'no force readings in the state samples';
    const commanded = sample.commandedPositions || [];
    const following = commanded.length === measured.length && measured.length;
    if (following) this.push('following', t, measured.map((q, i) => commanded[i] - q));
    this.missing.following = following ? '' : 'no setpoints in the state samples';
  }
}

class LivePlot {
  constructor(name, spec) {
    this.name = name;
    this.spec = spec;
    this.units = null;
    this.element = document.getElementById(`plot-${name}`);
    this.note = document.getElementById(`plot-${name}-note`);
    this.unitLabel = document.getElementById(`plot-${name}-unit`);
    const tick = (u, splits, axis, space, step) => splits.map((v) => tickText(v, step));
    this.plot = new uPlot({
      width: 10, height: HEIGHT,
      scales: { x: { time: false }, y: { range: (u, min, max) => this.range(min, max) } },
      axes: [{ values: tick, size: 30 }, { values: tick, size: 60, space: 24 }],
      legend: { live: false },
      series: [{}, ...spec.labels.map((label, i) => ({ label, stroke: COLORS[i % COLORS.length], width: 1.5 }))],
    }, [[], ...spec.labels.map(() => [])], this.element);
    new ResizeObserver(() => this.plot.setSize({ width: this.element.clientWidth, height: HEIGHT })).observe(this.element);
    this.seen = false;   // on screen: a plot scrolled away or folded is not drawn
    this.onSeen = () => {};
    new IntersectionObserver(([entry]) => {
      this.seen = entry.isIntersecting;
      if (this.seen) this.onSeen();
    }).observe(this.element);
  }

  range(min, max) {
    const span = this.spec.kind && this.units ? fromSI(this.spec.span, this.spec.kind, this.units) : this.spec.span;
    if (min === null || max === null) return [-span, span];
    if (max - min < span) {
      const middle = (min + max) / 2;
      return [middle - span / 2, middle + span / 2];
    }
    const pad = (max - min) * 0.05;
    return [min - pad, max + pad];
  }

  // The device's series for this plot, converted to its display units.
  show(data, units) {
    this.units = units;
    this.unitLabel.textContent = this.spec.unit(units);
    const [x, ...ys] = data.series[this.name];
    const convert = this.spec.kind ? (v) => (v === null ? null : fromSI(v, this.spec.kind, units)) : (v) => v;
    this.plot.setData([x.slice(), ...ys.map((y) => y.map(convert))]);
    this.note.textContent = data.missing[this.name] || '';
  }
}

export class Plots {
  constructor() {
    this.plots = Object.entries(PLOTS).map(([name, spec]) => new LivePlot(name, spec));
    this.pending = false;
    for (const plot of this.plots) plot.onSeen = () => { if (this.data) this.show(this.data, this.units); };
  }

  // Redrawn with the device's data at most REDRAW_HZ times a second, the plots on screen only,
  // one an animation frame: a plot needs no more, and each redraw takes the page's main thread
  // from the live state (several in one task would hold a sample back all the longer).
  show(data, units) {
    this.data = data;
    this.units = units;
    if (this.pending) return;
    this.pending = true;
    setTimeout(() => this.drawFrom(0), 1000 / REDRAW_HZ);
  }

  drawFrom(index) {
    const next = this.plots.findIndex((plot, i) => i >= index && plot.seen);
    if (next < 0) { this.pending = false; return; }
    requestAnimationFrame(() => {
      this.plots[next].show(this.data, this.units);
      this.drawFrom(next + 1);
    });
  }
}
