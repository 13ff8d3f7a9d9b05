// The 3D views of the cell's arms. Arms drawn in one scene need their places in one cell frame,
// which the devices do not give yet (GetCellDescription places each arm in its own world only:
// docs/page.md); until they do, each arm has a view of its own, side by side (on a narrow
// screen, the chosen arm's), each drawn the same way, and the page says why.
import { CellView } from './scene.js';
import { describeCell } from './words.js';

export class Scenes {
  constructor(container, selection) {
    this.views = new Map();    // device -> {view, box, note, stale}
    const several = selection.devices.size > 1;
    container.classList.toggle('several', several);
    document.getElementById('scenes-note').hidden = !several;
    for (const device of selection.devices.values()) {
      const box = document.createElement('div');
      box.className = 'cell-view';
      box.dataset.device = device.name;
      const canvas = document.createElement('canvas');
      canvas.setAttribute('role', 'img');
      canvas.setAttribute('aria-label', `${device.name} in 3D: drag to turn, wheel to zoom`);
      const note = document.createElement('div');
      note.className = 'scene-note';
      const stale = document.createElement('div');
      stale.className = 'scene-stale';
      stale.setAttribute('role', 'status');
      stale.hidden = true;
      box.append(canvas, note, stale);
      container.append(box);
      const view = new CellView(canvas);
      view.add(device.arm);
      view.onRatio = () => this.describe(device);
      this.views.set(device, { view, box, note, stale });
      this.describe(device);
    }
    selection.on((what, device) => {
      if (what === 'switch') this.views.forEach((v, d) => v.box.classList.toggle('selected', d === device));
      if (['robot', 'cell', 'fresh'].includes(what)) this.describe(device);
    });
    this.views.get(selection.device).box.classList.add('selected');
    // A stale view says for how long, to the second.
    setInterval(() => this.views.forEach((v, d) => { if (d.fresh.stale) this.describe(d); }), 1000);
    // For the console and the tests: the views and arms by device name.
    window.cellViews = Object.fromEntries([...this.views].map(([d, v]) => [d.name, v.view]));
    window.armViews = Object.fromEntries([...this.views].map(([d]) => [d.name, d.arm]));
  }

  // What a view shows, in one line, and whether it is live.
  describe(device) {
    const { view, note, stale, box } = this.views.get(device);
    const model = device.ctx.model;
    const resolution = view.resolutionNote();
    note.textContent = `${device.name}: ${describeCell(model.robotType, model.cell)}${resolution ? `; ${resolution}` : ''}`;
    stale.hidden = !device.fresh.stale;
    stale.textContent = device.fresh.stale ? `${device.name}: ${device.fresh.describe()}` : '';
    box.classList.toggle('stale', device.fresh.stale);
  }
}
