// One device's arm in 3D: the arm from its URDF (urdf-loader), the cell around it as the
// device describes it (GetCellDescription: fixtures, zones, tools in the rack or on the
// flange, parts where they lie or in the tool), the tool frame, the tool tip's trail, the
// path previewed, and a ghost arm previewing a goal. Everything is in meters and radians, z
// up, the device's world frame (`root`); the arm's base_link sits at the cell's base pose.
// Orientations are fixed-axis X-Y-Z roll, pitch, yaw (three.js order 'ZYX').
import * as THREE from 'three';
import URDFLoader from 'urdf-loader';

const TRAIL_POINTS = 600;
// Changes smaller than these are not drawn (rad, and m or rad for the tool pose).
const STILL_RAD = 1e-5;
const STILL_M = 1e-5;
const GHOST = { color: 0x4fc3f7, opacity: 0.35 };

function placePose(object, xyz, rpy) {
  object.position.set(xyz[0], xyz[1], xyz[2]);
  object.rotation.set(rpy[0], rpy[1], rpy[2], 'ZYX');
}

function colorOf(rgba) {
  return rgba && rgba.length >= 3 ? new THREE.Color(rgba[0], rgba[1], rgba[2]) : new THREE.Color(0x9e9e9e);
}

// A landscape.v1 Pose (JSON, SI) as a matrix.
export function poseMatrix(pose) {
  const object = new THREE.Object3D();
  placePose(object, [pose.x || 0, pose.y || 0, pose.z || 0], [pose.roll || 0, pose.pitch || 0, pose.yaw || 0]);
  object.updateMatrix();
  return object.matrix;
}

// A matrix as {x, y, z, roll, pitch, yaw} (SI).
export function matrixPose(matrix) {
  const position = new THREE.Vector3().setFromMatrixPosition(matrix);
  const euler = new THREE.Euler().setFromRotationMatrix(matrix, 'ZYX');
  return { x: position.x, y: position.y, z: position.z, roll: euler.x, pitch: euler.y, yaw: euler.z };
}

function setLocal(object, matrix) {
  matrix.decompose(object.position, object.quaternion, object.scale);
}

function makeLine(color, capacity) {
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute('position', new THREE.BufferAttribute(new Float32Array(capacity * 3), 3));
  geometry.setDrawRange(0, 0);
  return { line: new THREE.Line(geometry, new THREE.LineBasicMaterial({ color })), count: 0, capacity };
}

export class ArmView {
  // requestRender(): the view this arm is drawn in draws again.
  constructor(name, requestRender) {
    this.name = name;
    this.requestRender = requestRender;
    this.root = new THREE.Group();          // the device's world frame, in the view's frame
    this.root.name = name;
    this.base = new THREE.Group();          // the arm's base_link frame
    this.root.add(this.base);
    this.toolFrame = new THREE.AxesHelper(0.12);
    this.toolFrame.visible = false;
    this.base.add(this.toolFrame);
    this.trail = makeLine(0x1565c0, TRAIL_POINTS);
    this.base.add(this.trail.line);
    this.pathGroup = new THREE.Group();
    this.base.add(this.pathGroup);
    this.cell = null;                       // the newest GetCellDescription
    this.bodies = new Map();                // body name -> {object, attachedTo}
    this.tipOffset = new THREE.Matrix4();   // the tool tip in the flange frame
    this.endEffector = '';                  // "<tool> <state>" of the newest sample
    this.graspFlange = null;                // the flange (world) when the tool last acted,
                                            // if no cell description came since
    this.stale = false;
    this.onMoved = () => {};                // set by the view it is drawn in
  }

  // The arm, from the URDF text of DeviceService.GetRobotDescription: the one drawn, a ghost
  // (drawn only to preview a goal) and one never drawn, for the kinematics of previews.
  loadRobot(urdf) {
    const loader = new URDFLoader();
    if (this.robot) this.base.remove(this.robot, this.ghost);
    this.robot = loader.parse(urdf);
    this.base.add(this.robot);
    if (this.cell) {   // the bodies on the flange and in the tool go on this arm
      for (const item of this.bodies.values()) item.attachedTo = null;
      this.setCell(this.cell);
    }
    this.ghost = loader.parse(urdf);
    this.ghost.traverse((part) => {
      if (!part.isMesh) return;
      part.material = new THREE.MeshLambertMaterial({ ...GHOST, transparent: true, depthWrite: false });
      part.material.userData.ghost = true;
    });
    this.ghost.visible = false;
    this.base.add(this.ghost);
    this.kinematics = loader.parse(urdf);
    this.jointNames = Object.keys(this.robot.joints).filter((n) => this.robot.joints[n].jointType !== 'fixed');
    this.requestRender();
    return this.limits();
  }

  // [{name, lower, upper}] in radians, from the URDF.
  limits() {
    return this.jointNames.map((name) => {
      const limit = this.robot.joints[name].limit;
      return { name, lower: Number(limit.lower), upper: Number(limit.upper) };
    });
  }

  // The cell from GetCellDescription (JSON): bodies are made once, then only moved.
  setCell(cell) {
    this.cell = cell;
    const base = cell.base || {};
    placePose(this.base, [base.x || 0, base.y || 0, base.z || 0], [base.roll || 0, base.pitch || 0, base.yaw || 0]);
    this.root.updateMatrixWorld(true);
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
    if (this.stale) this.grey(true);
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
      this.root.add(object);
      placePose(object, [body.pose.x, body.pose.y, body.pose.z], [body.pose.roll, body.pose.pitch, body.pose.yaw]);
    } else if (!flange) {
      object.removeFromParent();   // drawn once the arm is loaded (loadRobot places it again)
      return;
    } else if (item.attachedTo !== body.attachedTo || object.parent !== flange) {
      let local = body.attachedTo === 'flange' ? new THREE.Matrix4() : this.tipOffset.clone();
      if (body.attachedTo === 'tool' && object.parent === this.root) {
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
    this.root.updateMatrixWorld(true);
    this.graspFlange = this.robot.links.tool0.matrixWorld.clone();
    const mounted = this.bodies.get(tool)?.object;
    for (const [name, joint] of Object.entries(mounted?.joints || {})) {
      if (joint.jointType === 'prismatic') mounted.setJointValue(name, state === 'open' ? joint.limit.upper : 0);
    }
    this.requestRender();
  }

  // Joint values in radians, joint 1 first; an arm at rest costs no frame. True when moved.
  setJoints(values) {
    if (!this.robot) return false;
    const last = this.shownJoints || [];
    if (values.length === last.length && values.every((q, i) => Math.abs(q - last[i]) < STILL_RAD)) return false;
    this.shownJoints = values;
    this.jointNames.forEach((name, i) => { if (i < values.length) this.robot.setJointValue(name, values[i]); });
    this.onMoved();
    this.requestRender();
    return true;
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
    this.jointNames.forEach((name, i) => this.kinematics.setJointValue(name, joints[i]));
    this.kinematics.updateMatrixWorld(true);
    return this.kinematics.links.tool0.matrixWorld.clone().multiply(poseMatrix(toolOffset));
  }

  // Where the tool tip is at these joint values, in the base frame.
  tipAt(joints, toolOffset) {
    return new THREE.Vector3().setFromMatrixPosition(this.tipMatrix(joints, toolOffset));
  }

  // A point {x, y, z} through a matrix.
  transformed(point, matrix) {
    return new THREE.Vector3(point.x, point.y, point.z).applyMatrix4(matrix);
  }

  // A path: its points ({x, y, z}: tool tip positions, base frame, meters) joined in order,
  // dashed; empty clears it.
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

  // The ghost arm at these joint values (radians), or hidden (null).
  showGhost(joints) {
    if (!this.ghost) return;
    this.ghost.visible = Boolean(joints);
    if (joints) this.jointNames.forEach((name, i) => this.ghost.setJointValue(name, joints[i]));
    this.requestRender();
  }

  // Stale: everything of this arm drawn grey, so an old picture is not taken for a live one.
  setStale(stale) {
    if (stale === this.stale) return;
    this.stale = stale;
    this.grey(stale);
    this.requestRender();
  }

  grey(on) {
    this.root.traverse((part) => {
      const material = part.material;
      if (!material?.color || material.userData.ghost) return;
      if (on && !material.userData.live) {
        material.userData.live = material.color.clone();
        const hsl = material.color.getHSL({});
        material.color.setHSL(hsl.h, 0, 0.35 + hsl.l * 0.4);
      } else if (!on && material.userData.live) {
        material.color.copy(material.userData.live);
        delete material.userData.live;
      }
    });
  }
}
