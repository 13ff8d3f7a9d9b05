// The cell in 3D: the arm from the device's URDF (urdf-loader), the cell around it as the device
// describes it (DeviceService.GetCellDescription: fixtures, zones, tools in the rack or on the
// flange, parts where they lie or in the tool), the tool frame, the tool tip's trail and the
// loaded path. Everything is in meters and radians, z up, the cell's world frame; the arm's
// base_link sits at the cell's base pose. Orientations are fixed-axis X-Y-Z roll, pitch, yaw
// (three.js order 'ZYX').
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
  return rgba && rgba.length >= 3 ? new THREE.Color(rgba[0], rgba[1], rgba[2]) : new THREE.Color(0x9e9e9e);
}

// A landscape.v1 Pose (JSON) as a matrix.
export function poseMatrix(pose) {
  const object = new THREE.Object3D();
  placePose(object, [pose.x, pose.y, pose.z], [pose.roll, pose.pitch, pose.yaw]);
  object.updateMatrix();
  return object.matrix;
}

function setLocal(object, matrix) {
  matrix.decompose(object.position, object.quaternion, object.scale);
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
    this.grid = new THREE.GridHelper(4, 20, 0x888888, 0xcccccc);
    this.grid.rotation.x = Math.PI / 2;   // GridHelper lies in x-z; the floor is x-y
    this.scene.add(this.grid);

    this.base = new THREE.Group();          // the arm's base_link frame
    this.scene.add(this.base);
    this.toolFrame = new THREE.AxesHelper(0.12);
    this.toolFrame.visible = false;
    this.base.add(this.toolFrame);
    this.trail = this.makeLine(0x1565c0, TRAIL_POINTS);
    this.base.add(this.trail.line);
    this.pathGroup = new THREE.Group();
    this.base.add(this.pathGroup);
    this.cell = null;                       // the newest GetCellDescription
    this.bodies = new Map();                // body name -> {object, attachedTo}
    this.tipOffset = new THREE.Matrix4();   // the tool tip in the flange frame
    this.endEffector = '';                  // "<tool> <state>" of the newest sample
    this.graspFlange = null;                // the flange (world) when the tool last acted,
                                            // if no cell description came since

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
    if (this.cell) {   // the bodies on the flange and in the tool go on this arm
      for (const item of this.bodies.values()) item.attachedTo = null;
      this.setCell(this.cell);
    }
    this.requestRender();
    this.ghost = loader.parse(urdf);        // never drawn: forward kinematics of path points
    this.jointNames = Object.keys(this.robot.joints).filter((n) => this.robot.joints[n].jointType !== 'fixed');
    return this.jointNames.map((name) => {
      const limit = this.robot.joints[name].limit;
      return { name, lower: limit.lower, upper: limit.upper };
    });
  }

  // The cell from GetCellDescription (JSON): bodies are made once, then only moved.
  setCell(cell) {
    this.cell = cell;
    const base = cell.base || {};
    placePose(this.base, [base.x || 0, base.y || 0, base.z || 0], [base.roll || 0, base.pitch || 0, base.yaw || 0]);
    this.grid.visible = Boolean(cell.floor);
    this.scene.updateMatrixWorld(true);
    const names = new Set();
    for (const body of cell.bodies || []) {
      names.add(body.name);
      if (!this.bodies.has(body.name)) this.bodies.set(body.name, { object: this.makeBody(body), attachedTo: null });
      this.place(this.bodies.get(body.name), body);
    }
    for (const [name, item] of this.bodies) {
      if (!names.has(name)) { item.object.removeFromParent(); this.bodies.delete(name); }
    }
    this.graspFlange = null;
    this.requestRender();
  }

  makeBody(body) {
    if (body.kind === 'KIND_TOOL') return new URDFLoader().parse(body.urdf);   // root: the mounting plate
    const size = body.size || { x: 0, y: 0, z: 0 };
    const box = new THREE.BoxGeometry(size.x, size.y, size.z);
    if (body.kind === 'KIND_ZONE') {
      return new THREE.LineSegments(new THREE.EdgesGeometry(box), new THREE.LineBasicMaterial({ color: 0x2e7d32 }));
    }
    const mesh = new THREE.Mesh(box, new THREE.MeshLambertMaterial({ color: colorOf(body.color) }));
    mesh.name = body.name;
    return mesh;
  }

  // A body in the world, on the flange (a mounted tool) or in the tool (a held part). A part
  // keeps where it was in the tool when taken: from the flange then to where it lay. The tool
  // acts at rest, so the flange then is the one when the sample said so (graspFlange) or, if
  // the description came first, the one shown now. A part first seen held is drawn at the tip.
  place(item, body) {
    const object = item.object;
    const flange = this.robot?.links.tool0;
    if (!body.attachedTo) {
      this.scene.add(object);
      placePose(object, [body.pose.x, body.pose.y, body.pose.z], [body.pose.roll, body.pose.pitch, body.pose.yaw]);
    } else if (!flange) {
      object.removeFromParent();   // drawn once the arm is loaded (loadRobot places it again)
      return;
    } else if (item.attachedTo !== body.attachedTo || object.parent !== flange) {
      let local = body.attachedTo === 'flange' ? new THREE.Matrix4() : this.tipOffset.clone();
      if (body.attachedTo === 'tool' && object.parent === this.scene) {
        object.updateMatrixWorld(true);
        const grasp = this.graspFlange || flange.matrixWorld;
        local = grasp.clone().invert().multiply(object.matrixWorld);
      }
      flange.add(object);
      setLocal(object, local);
    }
    item.attachedTo = body.attachedTo;
  }

  // The tip of the tool in the flange frame (GetToolOffsets, meters and radians).
  setTipOffset(pose) {
    this.tipOffset = poseMatrix(pose);
  }

  // The tool on the flange and its state, from every sample: the flange's pose when the state
  // changes is where a part was taken; a gripper's fingers open and close.
  setEndEffector(tool, state) {
    const now = `${tool} ${state}`;
    if (now === this.endEffector || !this.robot) return;
    this.endEffector = now;
    this.scene.updateMatrixWorld(true);
    this.graspFlange = this.robot.links.tool0.matrixWorld.clone();
    const mounted = this.bodies.get(tool)?.object;
    for (const [name, joint] of Object.entries(mounted?.joints || {})) {
      if (joint.jointType === 'prismatic') mounted.setJointValue(name, state === 'open' ? joint.limit.upper : 0);
    }
    this.requestRender();
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

  // The tool tip in the base frame at these joint values (radians), as a matrix; toolOffset is
  // the tip in the flange frame (meters, radians).
  tipMatrix(joints, toolOffset) {
    this.jointNames.forEach((name, i) => this.ghost.setJointValue(name, joints[i]));
    this.ghost.updateMatrixWorld(true);
    return this.ghost.links.tool0.matrixWorld.clone().multiply(poseMatrix(toolOffset));
  }

  // Where the tool tip is at these joint values, in the base frame.
  tipAt(joints, toolOffset) {
    return new THREE.Vector3().setFromMatrixPosition(this.tipMatrix(joints, toolOffset));
  }

  // A point {x, y, z} through a matrix.
  transformed(point, matrix) {
    return new THREE.Vector3(point.x, point.y, point.z).applyMatrix4(matrix);
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
