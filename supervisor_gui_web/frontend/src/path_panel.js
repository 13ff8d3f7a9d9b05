// The paths panel of the selected device: teach (store the current pose as a tag of a named
// path), load points typed in, clear, run, stop, resume, abort; the device's stored paths
// (paths.js), each previewed in 3D (its points read from the device, dashed, the ghost arm at
// its first point) before it runs; and the progress of the newest run by tag.
import { ENDED, tagKey } from './paths.js';
import { poseToSI, fromSI, toSI } from './units.js';
import { frameWord } from './words.js';

const $ = (id) => document.getElementById(id);
const JOINT_FRAME = 'REFERENCE_FRAME_JOINT_FRAME';

export class PathPanel {
  constructor(selection) {
    this.selection = selection;
    this.previewed = null;   // the path chosen in the list, drawn until another is
    this.drawn = 0;          // the newest draw; an older one still computing gives way
    const book = () => selection.device.paths;
    const on = (id, handler) => $(id).addEventListener('click', handler);
    on('btn-teach', () => this.teach());
    on('btn-path-load', () => this.loadTyped());
    on('btn-path-clear', () => book().clear($('path-name').value));
    on('btn-path-run', () => book().start($('path-name').value, Number($('path-cycles').value)));
    on('btn-stop', () => selection.ctx.command('StopMotion'));
    on('btn-resume', () => selection.ctx.command('ResumeMotion'));
    on('btn-abort', () => selection.ctx.command('AbortMotion'));
    // Another client may have loaded or cleared a path: the list is read again when opened.
    $('path-list').closest('details').addEventListener('toggle', (event) => {
      if (event.target.open) book().refresh();
    });
    $('path-name').addEventListener('input', () => { this.previewed = null; this.show(); });
    selection.on((what, device) => {
      if (what === 'switch') {
        for (const other of selection.devices.values()) if (other !== device) this.erase(other);
        this.previewed = null;
        device.paths.refresh();
      }
      if (device === selection.device && ['switch', 'paths', 'robot'].includes(what)) this.show();
    });
  }

  // The current joint values, in the device's units, as one more tag of the named path.
  teach() {
    const { ctx, paths } = this.selection.device;
    const sample = ctx.model.sample;
    if (!sample) return null;
    const units = ctx.model.units;
    const name = $('path-name').value;
    const known = paths.paths.get(name);
    const count = known?.length ?? 0;
    const tagName = $('teach-tag').value || `t${count + 1}`;
    const jointValues = sample.jointPositions.map((q) => fromSI(toSI(q, 'angular', sample.units), 'angular', units));
    $('teach-tag').value = '';
    return paths.load(name, JOINT_FRAME, 'MOTION_TYPE_JOINT_MOTION', [{ tagName, tagIndex: count, jointValues }]);
  }

  // Lines "tag v1 … v6" in the device's units: joint values, or x y z roll pitch yaw.
  loadTyped() {
    const frame = $('path-frame').value;
    const tags = [];
    $('path-points').value.split('\n').map((l) => l.trim()).filter(Boolean).forEach((line, i) => {
      const [tagName, ...rest] = line.split(/\s+/);
      const values = rest.map(Number);
      const tag = { tagName, tagIndex: i };
      if (frame === JOINT_FRAME) tag.jointValues = values;
      else ['x', 'y', 'z', 'roll', 'pitch', 'yaw'].forEach((k, j) => { tag[k] = values[j]; });
      tags.push(tag);
    });
    // Bad numbers go to the server as they are (NaN as JSON null fails to parse there too).
    return this.selection.device.paths.load($('path-name').value, frame, $('path-motion').value, tags);
  }

  // The path drawn: the one chosen in the list, else the newest run's while it lasts (or
  // once ended, unless another known path is typed), else the typed one.
  shownName() {
    const book = this.selection.device.paths;
    const typed = $('path-name').value;
    if (this.previewed && book.paths.has(this.previewed)) return this.previewed;
    const run = book.run;
    if (run && !(ENDED.has(run.phase) && typed !== run.path && book.paths.has(typed))) return run.path;
    return typed;
  }

  show() {
    const book = this.selection.device.paths;
    const name = this.shownName();
    const run = book.run?.path === name ? book.run : null;
    const box = $('path-progress');
    box.replaceChildren();
    if (run) {
      const head = document.createElement('div');
      head.textContent = book.progress(run);
      box.append(head);
    }
    // Known tags by name, the reached ones green; else the run's tags reached so far.
    const known = book.namedTags(name) || book.paths.get(name)?.tags.filter((t) => t.tagName) || [];
    const chips = known.length ? known.map((tag) => [tag.tagName, run?.reached.has(tagKey(tag))])
      : [...(run?.reached.values() || [])].map((tagName) => [tagName, true]);
    for (const [tagName, reached] of chips) {
      const item = document.createElement('span');
      item.className = `tag ${reached ? 'reached' : ''}`;
      item.textContent = tagName;
      box.append(item);
    }
    this.list(book, name);
    this.draw(book.paths.get(name));
  }

  list(book, shown) {
    const items = [...book.paths].map(([name, path]) => {
      const li = document.createElement('li');
      const preview = document.createElement('button');
      preview.className = 'path-preview';
      preview.textContent = name;
      preview.setAttribute('aria-pressed', String(name === shown));
      preview.title = `preview ${name} in 3D`;
      preview.addEventListener('click', () => this.preview(name));
      const about = document.createElement('span');
      about.className = 'note';
      const points = path.length === null ? 'points not known here'
        : path.length === path.tags.length ? `${path.length} points`
          : path.source === 'stored on the device' ? `${path.length} points (read when previewed)`
            : `${path.length} points, ${path.tags.length} known here`;
      about.textContent = ` ${points}${path.frame ? `, ${frameWord(path.frame)}` : ''}; ${path.source}`;
      li.append(preview, about);
      return li;
    });
    $('path-list').replaceChildren(...items);
    $('path-list-empty').hidden = items.length > 0;
    $('path-list-source').textContent = book.unlisted
      ? `The device did not list its stored paths (${book.unlisted}): these are the paths this page loaded, taught or saw running.`
      : 'The paths stored on the device, whoever loaded them.';
  }

  // A path chosen in the list: its points read from the device unless known, then drawn.
  async preview(name) {
    const { ctx, paths } = this.selection.device;
    this.previewed = name;
    $('path-name').value = name;
    if (paths.paths.get(name)?.source === 'stored on the device' && !paths.whole(name)) {
      const refused = await paths.read(name);
      if (refused) ctx.refused('GetPath', refused);
    }
    this.show();
  }

  erase(device) {
    device.arm.setPath([]);
    device.arm.showGhost(null);
  }

  // The known points as tool tip positions in the base frame (meters): joint values through
  // the arm's kinematics, base points as they are, world points through the device's world
  // frame; the ghost arm stands at a joint path's first point.
  async draw(path) {
    const device = this.selection.device;
    const arm = device.arm;
    const drawing = ++this.drawn;
    if (!path || !path.tags.length || !arm.robot) { this.erase(device); return; }
    const units = path.units || device.ctx.model.units;
    const toolOffset = device.toolOffset();
    const world = path.frame === 'REFERENCE_FRAME_WORLD_CARTESIAN_FRAME' ? await device.worldInBase() : null;
    if (drawing !== this.drawn) return;
    const joints = (tag) => tag.jointValues.map((v) => toSI(v, 'angular', units));
    const points = path.tags.map((tag) => {
      if (path.frame === JOINT_FRAME) return arm.tipAt(joints(tag), toolOffset);
      const p = poseToSI({ x: tag.x, y: tag.y, z: tag.z, roll: 0, pitch: 0, yaw: 0 }, units);
      const point = { x: p.x, y: p.y, z: p.z };
      return world ? arm.transformed(point, world) : point;
    });
    arm.setPath(points);
    arm.showGhost(path.frame === JOINT_FRAME && this.previewed ? joints(path.tags[0]) : null);
  }
}
