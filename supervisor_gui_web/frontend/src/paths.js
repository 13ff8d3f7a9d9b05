// One device's paths as the page knows them, and the progress of its newest path run.
//
// The contract has no call that lists a device's stored paths or reads their points
// (docs/page.md): the page knows the paths loaded or taught from it (their points, and the
// device's count of points from PathLoad's reply, which also counts points stored before),
// and the names of paths it saw run. A run's progress comes from the event stream, whoever
// started it: the tags reached in the current cycle, out of the path's tags when the page
// knows every point. A tag is known by its name and index (a client may leave every index
// 0); reaching one already reached in this cycle starts the next.
import { phaseWord } from './words.js';

export const ENDED = new Set(['done', 'failed', 'aborted']);
const RUNNING = new Set(['PHASE_STARTED', 'PHASE_RESUMED']);

// A tag as its events name it (TagStruct JSON and CommandEvent spell both fields alike).
export const tagKey = (tag) => `${tag.tagIndex || 0}:${tag.tagName}`;

export class PathBook {
  constructor(ctx) {
    this.ctx = ctx;
    this.paths = new Map();   // name -> {frame, motionType, tags, length (device's), source}
    this.run = null;          // {commandId, path, phase, cycles, cycle, reached: Set, last}
  }

  // PathLoad of `tags` (TagStruct JSON, device units) onto path `name`; true when loaded.
  async load(name, frame, motionType, tags) {
    const header = { pathName: name, frame, motionType, offsetType: 'OFFSET_TYPE_ABSOLUTE_DATA', numberOfPoints: tags.length };
    const reply = await this.ctx.command('PathLoad', [{ header, tags }], { streamed: true });
    if (!reply) return false;
    const known = this.paths.get(name);
    // Points appended to what the page knows in the same frame; otherwise only the new ones
    // are known (the device resolves every point to joints, whatever its frame).
    const base = known && known.frame === frame ? known.tags : [];
    this.paths.set(name, { frame, motionType, tags: [...base, ...tags], length: reply.pathLength, source: 'loaded here' });
    this.ctx.changed('paths');
    return true;
  }

  async clear(name) {
    if (!await this.ctx.command('PathClearPath', { pathName: name })) return false;
    this.paths.delete(name);
    this.ctx.changed('paths');
    return true;
  }

  async start(name, cycles) {
    const reply = await this.ctx.command('PathMove', { pathName: name, numberOfCycles: cycles });
    if (!reply) return reply;
    // Its started event may have come first: the run is followed already, without its cycles.
    if (this.run?.commandId === reply.retVal.commandId) this.run.cycles = cycles;
    else this.follow(reply.retVal.commandId, name, cycles);
    this.ctx.changed('paths');
    return reply;
  }

  follow(commandId, path, cycles = null) {
    this.run = { commandId, path, phase: 'running', cycles, cycle: 1, reached: new Map() };   // tag key -> name
    if (!this.paths.has(path)) this.paths.set(path, { frame: '', motionType: '', tags: [], length: null, source: 'seen running' });
    this.ctx.changed('paths');
  }

  // A landscape.v1.Event: a PathMove started by any client (its point name is the path's), the
  // tags it reaches and its end. A tag whose index is not past the last one reached starts
  // the path's next cycle.
  event(event) {
    const c = event.command;
    if (!c || c.command !== 'PathMove') return;
    if (c.phase === 'PHASE_STARTED' && this.run?.commandId !== c.commandId) this.follow(c.commandId, c.pointName);
    const run = this.run;
    if (c.commandId !== run?.commandId) return;
    if (c.phase === 'PHASE_TAG_REACHED') {
      const key = tagKey(c);
      if (run.reached.has(key)) { run.cycle += 1; run.reached.clear(); }
      run.reached.set(key, c.tagName);
    } else {
      run.phase = RUNNING.has(c.phase) ? 'running' : phaseWord(c.phase);
    }
    this.ctx.changed('paths');
  }

  // The tags of a path that raise events (the named ones), when the page knows every point.
  namedTags(name) {
    const path = this.paths.get(name);
    if (!path || path.length !== path.tags.length) return null;
    return path.tags.filter((tag) => tag.tagName);
  }

  // "run 12 of tour: moving, cycle 2 of 3, 1/4 tags reached".
  progress(run = this.run) {
    const named = this.namedTags(run.path);
    const cycles = run.cycles > 1 ? `cycle ${run.cycle} of ${run.cycles}, ` : run.cycle > 1 ? `cycle ${run.cycle}, ` : '';
    const count = named ? `${run.reached.size}/${named.length}` : `${run.reached.size}`;
    return `run ${run.commandId} of ${run.path}: ${run.phase}, ${cycles}${count} tags reached`;
  }
}
