// Live plots (uPlot): the force sensor and the joints' following error, over a sliding window.
import uPlot from 'uplot';
import 'uplot/dist/uPlot.min.css';

const WINDOW_S = 10;
const REDRAW_HZ = 5;
const COLORS = ['#c62828', '#2e7d32', '#1565c0', '#ef6c00', '#6a1b9a', '#00838f'];

class LivePlot {
  constructor(element, labels) {
    this.element = element;
    this.data = [[], ...labels.map(() => [])];
    this.plot = new uPlot({
      width: 10, height: 150,
      scales: { x: { time: false } },
      axes: [{ label: 's' }, {}],
      legend: { live: false },
      series: [{}, ...labels.map((label, i) => ({ label, stroke: COLORS[i % COLORS.length], width: 1.5 }))],
    }, this.data, element);
    new ResizeObserver(() => this.plot.setSize({ width: element.clientWidth, height: 150 })).observe(element);
    this.pending = false;
  }

  // Redrawn after new points, at most REDRAW_HZ times a second: a plot needs no more, and each
  // redraw takes the page's main thread from the live state.
  redraw() {
    if (this.pending) return;
    this.pending = true;
    setTimeout(() => requestAnimationFrame(() => { this.pending = false; this.plot.setData(this.data); }),
      1000 / REDRAW_HZ);
  }

  // One point per series at time t (seconds).
  push(t, values) {
    const [x, ...ys] = this.data;
    x.push(t);
    ys.forEach((y, i) => y.push(values[i] ?? null));
    while (x.length && x[0] < t - WINDOW_S) { x.shift(); ys.forEach((y) => y.shift()); }
    this.redraw();
  }
}

export class Plots {
  constructor() {
    this.force = new LivePlot(document.getElementById('plot-force'), ['fx', 'fy', 'fz']);
    this.following = new LivePlot(document.getElementById('plot-following'), ['J1', 'J2', 'J3', 'J4', 'J5', 'J6']);
    this.forceNote = document.getElementById('plot-force-note');
    this.followingNote = document.getElementById('plot-following-note');
  }

  // A StateSample (JSON); t in seconds; toDisplay converts an angle from the sample's units.
  add(sample, t, toDisplay) {
    const force = (sample.sensors || []).find((s) => s.name === 'force_sensor');
    if (force) {
      this.force.push(t, force.values.slice(0, 3));
      this.forceNote.textContent = '';
    } else {
      this.forceNote.textContent = 'no force readings in the state samples';
    }
    const measured = sample.jointPositions || [];
    const commanded = sample.commandedPositions || [];
    if (commanded.length === measured.length && measured.length) {
      this.following.push(t, measured.map((q, i) => toDisplay(commanded[i] - q)));
      this.followingNote.textContent = '';
    } else {
      this.followingNote.textContent = 'no setpoints in the state samples';
    }
  }
}
