// The cell in 3D: the arm from the device's URDF (urdf-loader), the world (table, rack, tools,
// parts, zones), the tool frame, the tool tip's trail and the loaded path.
// Everything is in meters and radians, z up, the cell's world frame; the arm's base_link sits at
// the cell's base pose. Orientations are fixed-axis X-Y-Z roll, pitch, yaw (three.js order 'ZYX').
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import URDFLoader from 'urdf-loader';

const TRAIL_POINTS = 600;
const SOFTWARE_FPS = 15;
// Changes smaller than these are not drawn (rad, and m or rad for the tool pose).
const STILL_RAD = 1e-5;
const STILL_M = 1e-5;

function rendererName(renderer) {
  const gl = renderer.getContext();
  const info = gl.getExtension('WEBGL_debug_renderer_info');
  return info ? gl.getParameter(info.UNMASKED_RENDERER_WEBGL) : gl.getParameter(gl.RENDERER);
}

function placePose(object, xyz, rpy) {
  object.position.set(xyz[0], xyz[1], xyz[2]);
  object.rotation.set(rpy[0], rpy[1], rpy[2], 'ZYX');
}

function colorOf(rgba) {
  return new THREE.Color(rgba[0], rgba[1], rgba[2]);
}

export class CellView {
  constructor(canvas) {
    THREE.Object3D.DEFAULT_UP.set(0, 0, 1);
    this.canvas = canvas;
    this.renderer = new THREE.WebGLRenderer({ canvas, antialias: false });
    // Without a GPU (a software rasterizer such as SwiftShader) every pixel costs the page's
    // CPU: draw at half resolution and at most SOFTWARE_FPS frames a second, so the live
    // state never waits long behind a frame.
    // ?render=full keeps full resolution and rate all the same (for pictures of the page).
    const full = new URLSearchParams(location.search).get('render') === 'full';
    this.software = !full && /swiftshader|llvmpipe|software/i.test(rendererName(this.renderer));
    this.renderer.setPixelRatio(this.software ? 0.5 : window.devicePixelRatio);
    this.minFrameMs = this.software ? 1000 / SOFTWARE_FPS : 0;
    this.lastFrame = 0;
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(0xe8ecef);
    this.camera = new THREE.PerspectiveCamera(45, 1, 0.05, 50);
    this.camera.up.set(0, 0, 1);
    this.camera.position.set(1.75, 1.25, 1.15);
    this.controls = new OrbitControls(this.camera, canvas);
    this.controls.target.set(0.25, -0.1, 0.45);
    this.controls.update();
    this.controls.addEventListener('change', () => this.requestRender());

    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x8d8d8d, 2.0));
    const sun = new THREE.DirectionalLight(0xffffff, 2.0);
    sun.position.set(2, 1, 4);
    this.scene.add(sun);
    const grid = new THREE.GridHelper(4, 20, 0x888888, 0xcccccc);
    grid.rotation.x = Math.PI / 2;   // GridHelper lies in x-z; the floor is x-y
    this.scene.add(grid);

    this.base = new THREE.Group();          // the arm's base_link frame
    this.scene.add(this.base);
    this.toolFrame = new THREE.AxesHelper(0.12);
    this.toolFrame.visible = false;
    this.base.add(this.toolFrame);
    this.trail = this.makeLine(0x1565c0, TRAIL_POINTS);
    this.base.add(this.trail.line);
    this.pathGroup = new THREE.Group();
    this.base.add(this.pathGroup);
    this.tools = new Map();                 // tool name -> {mesh, slotParent, slot}

    new ResizeObserver(() => this.resize()).observe(canvas.parentElement);
    this.resize();
  }

  // Draw once in the next animation frame, and only when something changed: a software-rendered
  // frame costs the page's main thread milliseconds that the live state would wait behind.
  requestRender() {
    if (this.renderPending) return;
    this.renderPending = true;
    const wait = Math.max(0, this.lastFrame + this.minFrameMs - performance.now());
    setTimeout(() => requestAnimationFrame(() => {
      this.renderPending = false;
      this.lastFrame = performance.now();
      this.renderer.render(this.scene, this.camera);
    }), wait);
  }

  resize() {
    const { clientWidth: w, clientHeight: h } = this.canvas.parentElement;
    if (!w || !h) return;
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.requestRender();
  }

  makeLine(color, capacity) {
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute('position', new THREE.BufferAttribute(new Float32Array(capacity * 3), 3));
    geometry.setDrawRange(0, 0);
    return { line: new THREE.Line(geometry, new THREE.LineBasicMaterial({ color })), count: 0, capacity };
  }

  // The arm, from the URDF text of DeviceService.GetRobotDescription.
  loadRobot(urdf) {
    const loader = new URDFLoader();
    if (this.robot) this.base.remove(this.robot);
    this.robot = loader.parse(urdf);
    this.base.add(this.robot);
    this.requestRender();
    this.ghost = loader.parse(urdf);        // never drawn: forward kinematics of path points
    this.jointNames = Object.keys(this.robot.joints).filter((n) => this.robot.joints[n].jointType !== 'fixed');
    return this.jointNames.map((name) => {
      const limit = this.robot.joints[name].limit;
      return { name, lower: limit.lower, upper: limit.upper };
    });
  }

  // The world from the cell description (cell_world.py): poses in meters and radians.
  loadWorld(cell) {
    placePose(this.base, cell.base.xyz, cell.base.rpy);
    const world = cell.world;
    for (const box of [...world.fixtures, ...world.parts]) {
      const mesh = new THREE.Mesh(new THREE.BoxGeometry(...box.size),
        new THREE.MeshLambertMaterial({ color: colorOf(box.color) }));
      placePose(mesh, box.pose.xyz, box.pose.rpy);
      mesh.name = box.name;
      this.scene.add(mesh);
    }
    for (const zone of world.zones) {
      const edges = new THREE.LineSegments(new THREE.EdgesGeometry(new THREE.BoxGeometry(...zone.size)),
        new THREE.LineBasicMaterial({ color: 0x2e7d32 }));
      edges.position.set(...zone.center);
      this.scene.add(edges);
    }
    for (const tool of world.tools) this.addTool(tool);
    this.requestRender();
  }

  addTool(tool) {
    // The tool's frame is its mounting plate, z along the tool axis; the body hangs along +z.
    const slot = new THREE.Group();
    placePose(slot, tool.slot.xyz, tool.slot.rpy);
    this.scene.add(slot);
    const radius = tool.kind === 'vacuum_cup' ? tool.cup_radius : 0.035;
    const body = new THREE.Mesh(new THREE.CylinderGeometry(radius, 0.04, tool.length, 20),
      new THREE.MeshLambertMaterial({ color: tool.kind === 'vacuum_cup' ? 0x37474f : 0x78909c }));
    body.rotation.x = Math.PI / 2;          // three's cylinder runs along y
    body.position.z = tool.length / 2;
    const mount = new THREE.Group();
    mount.add(body);
    slot.add(mount);
    this.tools.set(tool.name, { mount, slot });
  }

  // Which tool is on the flange ('' for none): it rides on tool0, the others stay in the rack.
  setEndEffector(name) {
    if (!this.robot) return;
    const flange = this.robot.links.tool0;
    for (const [toolName, tool] of this.tools) {
      const parent = toolName === name && flange ? flange : tool.slot;
      if (tool.mount.parent !== parent) { parent.add(tool.mount); this.requestRender(); }
    }
  }

  // Joint values in radians, joint 1 first; an arm at rest costs no frame.
  setJoints(values) {
    if (!this.robot) return;
    const last = this.shownJoints || [];
    if (values.length === last.length && values.every((q, i) => Math.abs(q - last[i]) < STILL_RAD)) return;
    this.shownJoints = values;
    this.jointNames.forEach((name, i) => { if (i < values.length) this.robot.setJointValue(name, values[i]); });
    this.requestRender();
  }

  // The tool tip in the robot base frame, meters and radians: the tool frame and the trail.
  setToolPose(pose) {
    const last = this.shownPose;
    if (last && ['x', 'y', 'z', 'roll', 'pitch', 'yaw'].every((k) => Math.abs(pose[k] - last[k]) < STILL_M)) return;
    this.shownPose = pose;
    placePose(this.toolFrame, [pose.x, pose.y, pose.z], [pose.roll, pose.pitch, pose.yaw]);
    this.toolFrame.visible = true;
    const t = this.trail;
    const array = t.line.geometry.attributes.position.array;
    if (t.count === t.capacity) { array.copyWithin(0, 3); t.count -= 1; }
    array.set([pose.x, pose.y, pose.z], t.count * 3);
    t.count += 1;
    t.line.geometry.setDrawRange(0, t.count);
    t.line.geometry.attributes.position.needsUpdate = true;
    this.requestRender();
  }

  // Where the tool tip is at these joint values (radians), in the base frame; toolOffset is the
  // tip in the flange frame (meters, radians).
  tipAt(joints, toolOffset) {
    this.jointNames.forEach((name, i) => this.ghost.setJointValue(name, joints[i]));
    this.ghost.updateMatrixWorld(true);
    const tip = new THREE.Object3D();
    placePose(tip, [toolOffset.x, toolOffset.y, toolOffset.z], [toolOffset.roll, toolOffset.pitch, toolOffset.yaw]);
    tip.updateMatrix();
    const m = this.ghost.links.tool0.matrixWorld.clone().multiply(tip.matrix);
    return new THREE.Vector3().setFromMatrixPosition(m);
  }

  // The path as loaded: its points ({x, y, z}: tool tip positions, base frame, meters) joined
  // in order.
  setPath(xyz) {
    this.pathGroup.clear();
    this.requestRender();
    if (!xyz.length) return;
    const points = xyz.map((p) => new THREE.Vector3(p.x, p.y, p.z));
    const geometry = new THREE.BufferGeometry().setFromPoints(points);
    this.pathGroup.add(new THREE.Line(geometry, new THREE.LineDashedMaterial({ color: 0xef6c00, dashSize: 0.02, gapSize: 0.01 })).computeLineDistances());
    for (const p of points) {
      const dot = new THREE.Mesh(new THREE.SphereGeometry(0.012), new THREE.MeshBasicMaterial({ color: 0xef6c00 }));
      dot.position.copy(p);
      this.pathGroup.add(dot);
    }
  }
}
