// The 3D views of the cell's arms. When every device places its world in the same shared cell
// (GetCellDescription's world_in_cell and shared_cell, from the launcher's cell file), the arms
// are drawn in one scene, each where the cell file puts it. Otherwise each arm has a view of
// its own, side by side (on a narrow screen, the chosen arm's), and the page says why.
import { poseMatrix } from './arm_view.js';
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
    this.container = container;
    this.shared = '';   // the shared cell's name, once the arms are drawn in one scene
    selection.on((what, device) => {
      if (what === 'switch') this.views.forEach((v, d) => v.box.classList.toggle('selected', d === device || Boolean(this.shared)));
      if (what === 'cell') this.joinIfPlaced();
      if (['robot', 'cell', 'fresh'].includes(what)) this.describe(device);
    });
    this.views.get(selection.device).box.classList.add('selected');
    // A stale view says for how long, to the second.
    setInterval(() => this.views.forEach((v, d) => { if (d.fresh.stale) this.describe(d); }), 1000);
    // For the console and the tests: the views and arms by device name.
    window.cellViews = Object.fromEntries([...this.views].map(([d, v]) => [d.name, v.view]));
    window.armViews = Object.fromEntries([...this.views].map(([d]) => [d.name, d.arm]));
  }

  // Every arm into the first view, placed by its device's world_in_cell, once every device
  // places itself in the same shared cell (a device's cell arrives on its own: the last one
  // decides). The other views go.
  joinIfPlaced() {
    const devices = [...this.views.keys()];
    const cells = devices.map((device) => device.ctx.model.cell);
    if (this.shared || devices.length < 2 || !cells.every((c) => c && !c.refused && c.worldInCell && c.sharedCell)) return;
    if (new Set(cells.map((c) => c.sharedCell)).size !== 1) return;
    this.shared = cells[0].sharedCell;
    const first = this.views.get(devices[0]);
    devices.forEach((device, i) => {
      const own = this.views.get(device);
      if (own !== first) {
        own.view.remove(device.arm);
        own.view.renderer.dispose();
        own.box.remove();
        this.views.set(device, first);
      }
      first.view.place(device.arm, poseMatrix(cells[i].worldInCell));
    });
    first.box.classList.add('selected');
    first.box.dataset.device = devices.map((d) => d.name).join(' ');
    first.view.onRatio = () => this.describe(devices[0]);
    this.container.classList.remove('several');
    const note = document.getElementById('scenes-note');
    note.textContent = `The arms in one scene: cell “${this.shared}”, each where the cell file places it.`;
    note.hidden = false;
    window.cellViews = Object.fromEntries(devices.map((d) => [d.name, first.view]));
    this.describe(devices[0]);
  }

  // What a view shows, in one line, and whether it is live.
  describe(device) {
    const { view, note, stale, box } = this.views.get(device);
    // The devices drawn in this view: one, or every one in a shared scene.
    const shown = [...this.views].filter(([, v]) => v.view === view).map(([d]) => d);
    const resolution = view.resolutionNote();
    const lines = shown.map((d) => `${d.name}: ${describeCell(d.ctx.model.robotType, d.ctx.model.cell)}`);
    note.textContent = `${lines.join('; ')}${resolution ? `; ${resolution}` : ''}`;
    const staleOnes = shown.filter((d) => d.fresh.stale);
    stale.hidden = staleOnes.length === 0;
    stale.textContent = staleOnes.map((d) => `${d.name}: ${d.fresh.describe()}`).join('; ');
    box.classList.toggle('stale', staleOnes.length > 0);
  }
}
