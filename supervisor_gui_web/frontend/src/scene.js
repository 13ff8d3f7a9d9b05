// A 3D view on one canvas: a three.js scene with the arms given to it (ArmView), a camera the
// person turns and zooms (OrbitControls), lights and the floor grid. It draws only when
// something changed, at the device's pixel ratio as far as the GPU's limits allow.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';

// Without a GPU (a software rasterizer such as SwiftShader) every pixel costs the page's CPU:
// draw at most SOFTWARE_FPS frames a second at SOFTWARE_PIXEL_RATIO, so the live state never
// waits long behind a frame. ?render=full draws at the device's ratio and rate all the same
// (for pictures of the page).
const SOFTWARE_FPS = 15;
const SOFTWARE_PIXEL_RATIO = 0.5;
const MOVE_FRAMES_KEPT = 1000;

function keep(times, time) {
  times.push(time);
  if (times.length > MOVE_FRAMES_KEPT) times.shift();
}

function rendererName(renderer) {
  const gl = renderer.getContext();
  const info = gl.getExtension('WEBGL_debug_renderer_info');
  return info ? gl.getParameter(info.UNMASKED_RENDERER_WEBGL) : gl.getParameter(gl.RENDERER);
}

export class CellView {
  constructor(canvas) {
    THREE.Object3D.DEFAULT_UP.set(0, 0, 1);
    this.canvas = canvas;
    this.renderer = new THREE.WebGLRenderer({ canvas, antialias: false });
    const full = new URLSearchParams(location.search).get('render') === 'full';
    this.rendererName = rendererName(this.renderer);
    this.software = !full && /swiftshader|llvmpipe|software/i.test(this.rendererName);
    this.minFrameMs = this.software ? 1000 / SOFTWARE_FPS : 0;
    this.lastFrame = 0;
    this.ratio = 1;                 // the pixel ratio drawn at
    this.onRatio = () => {};        // (it changed)
    this.arms = [];
    // What the benchmarks read: frames drawn, when the first arm was, the samples that moved
    // an arm and the frames that showed it (page clock, ms).
    this.stats = { frames: 0, firstArmAt: null, moveSamples: [], moveFrames: [] };
    this.moved = false;
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

    new ResizeObserver(() => this.resize()).observe(canvas.parentElement);
    this.watchPixelRatio();
    this.resize();
  }

  // An arm drawn in this view; `placement`: its world frame in the view's (a Matrix4), or
  // none: the view's frame is the arm's world.
  add(arm, placement = null) {
    arm.requestRender = () => this.requestRender();
    arm.onMoved = () => {
      this.moved = true;
      keep(this.stats.moveSamples, performance.now());
    };
    if (placement) placement.decompose(arm.root.position, arm.root.quaternion, arm.root.scale);
    this.arms.push(arm);
    this.scene.add(arm.root);
    this.requestRender();
  }

  // An arm drawn here moved to another view.
  remove(arm) {
    this.arms = this.arms.filter((a) => a !== arm);
    this.scene.remove(arm.root);
    this.requestRender();
  }

  // An arm's world frame placed in the view's (a Matrix4).
  place(arm, placement) {
    if (!this.arms.includes(arm)) this.add(arm);
    placement.decompose(arm.root.position, arm.root.quaternion, arm.root.scale);
    arm.root.updateMatrixWorld(true);
    this.requestRender();
  }

  // The floor grid where any arm's cell has a floor.
  showFloor() {
    this.grid.visible = this.arms.some((arm) => arm.cell?.floor);
  }

  // Draw once in the next animation frame, and only when something changed: a software-rendered
  // frame costs the page's main thread milliseconds that the live state would wait behind.
  requestRender() {
    if (this.renderPending) return;
    this.renderPending = true;
    const wait = Math.max(0, this.lastFrame + this.minFrameMs - performance.now());
    setTimeout(() => requestAnimationFrame(() => this.draw()), wait);
  }

  draw() {
    this.renderPending = false;
    this.lastFrame = performance.now();
    this.showFloor();
    this.renderer.render(this.scene, this.camera);
    const stats = this.stats;
    stats.frames += 1;
    if (stats.firstArmAt === null && this.arms.some((arm) => arm.robot)) stats.firstArmAt = this.lastFrame;
    if (this.moved) {
      this.moved = false;
      keep(stats.moveFrames, this.lastFrame);
    }
  }

  // The device's pixel ratio, as far as the GPU draws a buffer that large (its largest
  // viewport and renderbuffer); less on a software rasterizer (above).
  pixelRatio(width, height) {
    const wanted = this.software ? Math.min(SOFTWARE_PIXEL_RATIO, window.devicePixelRatio) : window.devicePixelRatio;
    const gl = this.renderer.getContext();
    const largest = Math.min(gl.getParameter(gl.MAX_RENDERBUFFER_SIZE), ...gl.getParameter(gl.MAX_VIEWPORT_DIMS));
    return Math.min(wanted, largest / Math.max(width, height, 1));
  }

  // The window moved to a screen of another pixel ratio (or the page was zoomed): draw anew.
  watchPixelRatio() {
    const query = matchMedia(`(resolution: ${window.devicePixelRatio}dppx)`);
    query.addEventListener('change', () => { this.resize(); this.watchPixelRatio(); }, { once: true });
  }

  // Why the view draws fewer pixels than the screen has, or '' when it does not.
  resolutionNote() {
    if (this.ratio >= window.devicePixelRatio) return '';
    const rasterizer = /swiftshader|llvmpipe/i.exec(this.rendererName)?.[0] || 'a software rasterizer';
    const why = this.software ? `software rendering (${rasterizer}), no GPU` : 'the GPU\'s largest picture';
    return `drawn at ${Math.round(this.ratio * 100) / 100}× the screen's pixels: ${why}`;
  }

  resize() {
    const { clientWidth: w, clientHeight: h } = this.canvas.parentElement;
    if (!w || !h) return;
    const ratio = this.pixelRatio(w, h);
    this.renderer.setPixelRatio(ratio);
    if (ratio !== this.ratio) { this.ratio = ratio; this.onRatio(); }
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.requestRender();
  }
}
