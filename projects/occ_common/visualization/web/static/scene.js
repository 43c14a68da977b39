// The three.js scene: voxels as one instanced cube mesh, LiDAR points,
// camera frusta with their images; an orbit camera with z up; picking of
// the voxel under the pointer.
import * as THREE from 'three';
import {OrbitControls} from 'three/addons/controls/OrbitControls.js';

// Brightness of a cube's faces: top faces show the palette colour exactly
// (the browser tests look for it), the sides darker so that the shape
// reads without lights. BoxGeometry's faces: +x, -x, +y, -y, +z, -z.
const FACE_SHADES = [0.78, 0.78, 0.64, 0.64, 1.0, 0.5];
// Cubes a little smaller than their voxel leave a thin gap between them.
const CUBE_FILL = 0.94;
const NO_LABEL_COLOUR = [150, 150, 150];
const FRUSTUM_COLOUR = 0x222222;
// Stops of the height and intensity ramps (blue, cyan, green, yellow, red).
const RAMP = [[48, 18, 160], [30, 160, 220], [60, 200, 90], [240, 220, 40],
              [220, 40, 30]];

export function rampColour(t) {
  const x = Math.min(Math.max(t, 0), 1) * (RAMP.length - 1);
  const i = Math.min(Math.floor(x), RAMP.length - 2);
  const f = x - i;
  return RAMP[i].map((a, k) => a + (RAMP[i + 1][k] - a) * f);
}

function srgb(rgb) {
  return new THREE.Color().setRGB(rgb[0] / 255, rgb[1] / 255, rgb[2] / 255,
                                  THREE.SRGBColorSpace);
}

export class OccScene {
  constructor(container) {
    this.container = container;
    this.renderer = new THREE.WebGLRenderer({antialias: true});
    this.renderer.setPixelRatio(window.devicePixelRatio || 1);
    this.renderer.setClearColor(0xffffff);
    container.appendChild(this.renderer.domElement);
    this.scene = new THREE.Scene();
    this.camera = new THREE.PerspectiveCamera(50, 1, 0.1, 2000);
    this.camera.up.set(0, 0, 1);
    this.controls = new OrbitControls(this.camera,
                                      this.renderer.domElement);
    this.controls.addEventListener('change', () => this.render());
    this.pending = null;
    this.voxels = null;
    this.voxelIndex = null;
    this.points = null;
    this.frusta = new THREE.Group();
    this.scene.add(this.frusta);
    this.raycaster = new THREE.Raycaster();
    this.frameCount = 0;
    new ResizeObserver(() => this.resize()).observe(container);
    this.resize();
  }

  resize() {
    const {clientWidth: w, clientHeight: h} = this.container;
    if (!w || !h) return;
    this.renderer.setSize(w, h);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.render();
  }

  // Draw at the next animation frame, once however many changes asked
  // for it (a software renderer takes seconds a frame on a full grid).
  // Resolves when the frame is drawn.
  render() {
    if (!this.pending) {
      this.pending = new Promise(resolve => requestAnimationFrame(() => {
        this.pending = null;
        this.renderer.render(this.scene, this.camera);
        this.frameCount += 1;
        resolve();
      }));
    }
    return this.pending;
  }

  // Look at the whole grid from behind the car and above, `forward`
  // ('+x', '-y', ...) being the grid direction ahead of it.
  resetView(grid, forward) {
    const [x0, y0, z0, x1, y1, z1] = grid.pc_range;
    const sign = forward[0] === '-' ? -1 : 1;
    const ahead = forward[1] === 'x' ? [sign, 0] : [0, sign];
    const reach = Math.max(x1 - x0, y1 - y0) / 2;
    const cx = (x0 + x1) / 2, cy = (y0 + y1) / 2;
    // 1.6 x the half-width at 45 degrees: the grid's near edge and its
    // far corners are in view.
    const back = reach * 1.6 / Math.SQRT2;
    this.camera.position.set(cx - ahead[0] * back, cy - ahead[1] * back,
                             z0 + back);
    this.controls.target.set(cx, cy, (z0 + z1) / 2);
    this.controls.update();
    this.render();
  }

  // Put the camera at `position` looking at `target` (grid frame).
  setCamera(position, target) {
    this.camera.position.set(...position);
    this.controls.target.set(...target);
    this.controls.update();
    return this.render();
  }

  // Look through a camera: from its centre towards its image's centre,
  // with its vertical field of view.
  lookThrough(frustum) {
    const [c, tl, tr, br, bl] = frustum.map(p => new THREE.Vector3(...p));
    const centre = tl.clone().add(tr).add(br).add(bl).multiplyScalar(0.25);
    const top = tl.clone().add(tr).multiplyScalar(0.5).sub(c);
    const bottom = bl.clone().add(br).multiplyScalar(0.5).sub(c);
    this.camera.fov = THREE.MathUtils.radToDeg(top.angleTo(bottom));
    this.camera.position.copy(c);
    this.controls.target.copy(centre);
    this.camera.updateProjectionMatrix();
    this.controls.update();
    this.render();
  }

  // Draw the voxels `flat` (flat indices into the grid, C order) with
  // `colours` (sRGB 0-255, three per voxel).
  setVoxels(grid, flat, colours) {
    if (this.voxels) {
      this.scene.remove(this.voxels);
      this.voxels.geometry.dispose();
      this.voxels.dispose();
      this.voxels = null;
    }
    this.voxelIndex = flat;
    if (!grid.shape || flat.length === 0) {
      this.render();
      return;
    }
    const [, Y, Z] = grid.shape;
    const [vx, vy, vz] = grid.voxel_size;
    const [x0, y0, z0] = grid.pc_range;
    const geometry = new THREE.BoxGeometry(vx * CUBE_FILL, vy * CUBE_FILL,
                                           vz * CUBE_FILL);
    const shades = new Float32Array(24 * 3);
    FACE_SHADES.forEach((s, face) => shades.fill(s, face * 12,
                                                 face * 12 + 12));
    geometry.setAttribute('color', new THREE.BufferAttribute(shades, 3));
    const material = new THREE.MeshBasicMaterial({vertexColors: true});
    const mesh = new THREE.InstancedMesh(geometry, material, flat.length);
    const matrices = mesh.instanceMatrix.array;
    const linear = new Float32Array(flat.length * 3);
    const colour = new THREE.Color();
    for (let n = 0; n < flat.length; n++) {
      const f = flat[n];
      const i = Math.floor(f / (Y * Z)), j = Math.floor(f / Z) % Y;
      const k = f % Z;
      const m = n * 16;
      matrices[m] = matrices[m + 5] = matrices[m + 10] = matrices[m + 15] = 1;
      matrices[m + 12] = x0 + (i + 0.5) * vx;
      matrices[m + 13] = y0 + (j + 0.5) * vy;
      matrices[m + 14] = z0 + (k + 0.5) * vz;
      colour.setRGB(colours[3 * n] / 255, colours[3 * n + 1] / 255,
                    colours[3 * n + 2] / 255, THREE.SRGBColorSpace);
      linear[3 * n] = colour.r;
      linear[3 * n + 1] = colour.g;
      linear[3 * n + 2] = colour.b;
    }
    mesh.instanceColor = new THREE.InstancedBufferAttribute(linear, 3);
    mesh.computeBoundingSphere();
    this.voxels = mesh;
    this.scene.add(mesh);
    this.render();
  }

  // LiDAR points: `xyz` int16 centimetres, `colours` sRGB 0-255.
  setPoints(xyz, colours, size) {
    if (this.points) {
      this.scene.remove(this.points);
      this.points.geometry.dispose();
      this.points.material.dispose();
      this.points = null;
    }
    if (xyz && colours) {
      const positions = new Float32Array(xyz.length);
      for (let n = 0; n < xyz.length; n++) positions[n] = xyz[n] / 100;
      const linear = new Float32Array(colours.length);
      const colour = new THREE.Color();
      for (let n = 0; n < colours.length; n += 3) {
        colour.setRGB(colours[n] / 255, colours[n + 1] / 255,
                      colours[n + 2] / 255, THREE.SRGBColorSpace);
        linear[n] = colour.r;
        linear[n + 1] = colour.g;
        linear[n + 2] = colour.b;
      }
      const geometry = new THREE.BufferGeometry();
      geometry.setAttribute('position',
                            new THREE.BufferAttribute(positions, 3));
      geometry.setAttribute('color', new THREE.BufferAttribute(linear, 3));
      this.points = new THREE.Points(geometry, new THREE.PointsMaterial(
          {size, sizeAttenuation: false, vertexColors: true}));
      this.scene.add(this.points);
    }
    this.render();
  }

  // Frusta (centre + four corners per camera) with their images, when
  // `imageUrls` is given, on the far rectangle.
  setFrusta(cameras, imageUrls) {
    for (const child of [...this.frusta.children]) {
      this.frusta.remove(child);
      child.geometry.dispose();
      if (child.material.map) child.material.map.dispose();
      child.material.dispose();
    }
    const lines = [];
    for (const cam of cameras) {
      const [c, tl, tr, br, bl] = cam.frustum;
      for (const corner of [tl, tr, br, bl]) lines.push(...c, ...corner);
      for (const [a, b] of [[tl, tr], [tr, br], [br, bl], [bl, tl]]) {
        lines.push(...a, ...b);
      }
    }
    if (lines.length) {
      const geometry = new THREE.BufferGeometry();
      geometry.setAttribute('position', new THREE.Float32BufferAttribute(
          lines, 3));
      this.frusta.add(new THREE.LineSegments(
          geometry, new THREE.LineBasicMaterial({color: FRUSTUM_COLOUR})));
    }
    (imageUrls || []).forEach((url, k) => {
      const [, tl, tr, br, bl] = cameras[k].frustum;
      const geometry = new THREE.BufferGeometry();
      geometry.setAttribute('position', new THREE.Float32BufferAttribute(
          [...tl, ...tr, ...br, ...bl], 3));
      geometry.setAttribute('uv', new THREE.Float32BufferAttribute(
          [0, 1, 1, 1, 1, 0, 0, 0], 2));
      geometry.setIndex([0, 3, 1, 1, 3, 2]);
      const texture = new THREE.TextureLoader().load(url, () => this.render());
      texture.colorSpace = THREE.SRGBColorSpace;
      this.frusta.add(new THREE.Mesh(geometry, new THREE.MeshBasicMaterial(
          {map: texture, side: THREE.DoubleSide})));
    });
    this.render();
  }

  setFrustaVisible(visible) {
    this.frusta.visible = visible;
    this.render();
  }

  // Client pixel (x, y) of a point of the grid's frame.
  screenPosition(x, y, z) {
    const v = new THREE.Vector3(x, y, z).project(this.camera);
    const rect = this.renderer.domElement.getBoundingClientRect();
    return [rect.left + (v.x + 1) / 2 * rect.width,
            rect.top + (1 - v.y) / 2 * rect.height];
  }

  // Flat index of the voxel under client pixel (x, y), or -1.
  pick(x, y) {
    if (!this.voxels) return -1;
    const rect = this.renderer.domElement.getBoundingClientRect();
    const ndc = new THREE.Vector2(((x - rect.left) / rect.width) * 2 - 1,
                                  -((y - rect.top) / rect.height) * 2 + 1);
    this.raycaster.setFromCamera(ndc, this.camera);
    const hits = this.raycaster.intersectObject(this.voxels);
    return hits.length ? this.voxelIndex[hits[0].instanceId] : -1;
  }
}

export {NO_LABEL_COLOUR, srgb};
