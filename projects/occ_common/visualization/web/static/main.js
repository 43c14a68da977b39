// The occupancy viewer: loads samples (from the server of
// tools/misc/browse_occ.py, or embedded in an exported page), keeps the
// view state and turns it into the scene. window.occViewer is its
// programmatic face (used by the browser tests and handy in the console).
import {decodeMessage, gunzipBase64} from './message.js';
import {Panel} from './panel.js';
import {NO_LABEL_COLOUR, OccScene, rampColour} from './scene.js';

const NOT_DRAWN = 255;
const CAMERA_BIT = 1, LIDAR_BIT = 2;

// The voxels of `flat` not enclosed by six others of it (an enclosed one
// cannot be seen nor picked), and their colours: a solid block costs its
// shell only.
function exposed(shape, flat, colours) {
  const [X, Y, Z] = shape;
  const drawn = new Uint8Array(X * Y * Z);
  for (const f of flat) drawn[f] = 1;
  const kept = [], keptColours = [];
  flat.forEach((f, n) => {
    const i = Math.floor(f / (Y * Z)), j = Math.floor(f / Z) % Y;
    const k = f % Z;
    const enclosed = i > 0 && i < X - 1 && j > 0 && j < Y - 1 && k > 0 &&
        k < Z - 1 && drawn[f - Y * Z] && drawn[f + Y * Z] &&
        drawn[f - Z] && drawn[f + Z] && drawn[f - 1] && drawn[f + 1];
    if (!enclosed) {
      kept.push(f);
      keptColours.push(colours[3 * n], colours[3 * n + 1],
                       colours[3 * n + 2]);
    }
  });
  return [Uint32Array.from(kept), keptColours];
}

class Viewer {
  constructor(meta, source) {
    this.meta = meta;
    this.source = source;
    this.state = {index: meta.initial_index || 0, view: 'gt', mask: 'none',
                  hiddenClasses: new Set(), hiddenErrors: new Set(),
                  points: 'height', frusta: true, pointSize: 2};
    this.sample = null;
    this.timings = {};
    this.scene = new OccScene(document.getElementById('viewport'));
    this.panel = new Panel(document.getElementById('panel'), meta, this);
    const canvas = this.scene.renderer.domElement;
    canvas.addEventListener('pointermove', e => this.hover(e, false));
    canvas.addEventListener('click', e => this.hover(e, true));
    document.addEventListener('keydown', e => {
      if (e.target.tagName === 'INPUT' && e.target.type === 'range') return;
      if (e.key === 'ArrowRight' || e.key === 'n') this.step(1);
      if (e.key === 'ArrowLeft' || e.key === 'p') this.step(-1);
    });
  }

  setBusy(state, text) {
    document.body.dataset.state = state;
    document.getElementById('status').textContent = text || '';
  }

  async load(index) {
    const count = this.meta.num_samples;
    index = Math.min(Math.max(index, 0), count - 1);
    this.setBusy('loading', `loading sample ${index + 1} / ${count}`);
    const started = performance.now();
    try {
      const {buffer, imageUrls} = await this.source.sample(index);
      const fetched = performance.now();
      const sample = decodeMessage(buffer);
      sample.imageUrls = imageUrls;
      this.prepare(sample);
      this.sample = sample;
      this.state.index = index;
      if (!sample.sections[this.state.view]) {
        this.state.view = sample.sections.gt ? 'gt' :
            (sample.sections.pred ? 'pred' : 'gt');
      }
      if (!sample.sections.visibility) this.state.mask = 'none';
      this.scene.setFrusta(sample.header.cameras, imageUrls);
      this.scene.setFrustaVisible(this.state.frusta);
      this.panel.setThumbnails(sample.header.cameras, imageUrls,
                               k => this.scene.lookThrough(
                                   sample.header.cameras[k].frustum));
      if (!this.viewSet) {
        this.scene.resetView(sample.header.grid, sample.header.forward);
        this.viewSet = true;
      }
      this.redraw();
      await this.drawn();
      this.timings = {fetchMs: fetched - started,
                      shownMs: performance.now() - started,
                      sinceNavigationMs: performance.now(),
                      bytes: buffer.byteLength};
      document.body.dataset.sample = String(index);
      this.setBusy('ready');
    } catch (err) {
      console.error(err);
      this.setBusy('error', `sample ${index}: ${err.message}`);
    }
  }

  step(delta) {
    if (this.meta.num_samples > 1) this.load(this.state.index + delta);
  }

  // Per-sample lookups: class counts of the current view's grid, and the
  // rank of every predicted voxel in the `prob` section.
  prepare(sample) {
    const {pred} = sample.sections;
    if (sample.sections.prob && pred) {
      const rank = new Int32Array(pred.length).fill(-1);
      const empty = this.meta.empty_label;
      let n = 0;
      for (let f = 0; f < pred.length; f++) if (pred[f] !== empty) {
        rank[f] = n++;
      }
      sample.probRank = rank;
    }
  }

  visibleIn(f) {
    const vis = this.sample.sections.visibility;
    if (!vis || this.state.mask === 'none') return true;
    return (vis[f] & (this.state.mask === 'camera' ? CAMERA_BIT
                                                  : LIDAR_BIT)) !== 0;
  }

  redraw() {
    const s = this.sample.sections, st = this.state, meta = this.meta;
    const empty = meta.empty_label, ignore = meta.ignore_index;
    const flat = [], colours = [];
    const counts = new Array(meta.class_names.length).fill(0);
    const grid = st.view === 'errors' ? null : s[st.view];
    const n = (s.gt || s.pred || []).length;
    for (let f = 0; f < n; f++) {
      let rgb;
      if (grid) {
        const label = grid[f];
        if (label === empty || label === ignore || !this.visibleIn(f)) {
          continue;
        }
        counts[label] += 1;
        if (st.hiddenClasses.has(label)) continue;
        rgb = meta.palette[label];
      } else {
        const code = s.errors[f];
        if (code === NOT_DRAWN || !this.visibleIn(f)) continue;
        // An error voxel belongs to its GT class, or to the predicted one
        // where the GT is empty (a false positive).
        const label = code === 1 ? s.pred[f] : s.gt[f];
        counts[label] += 1;
        if (st.hiddenErrors.has(code) || st.hiddenClasses.has(label)) {
          continue;
        }
        rgb = meta.error_palette[code];
      }
      flat.push(f);
      colours.push(rgb[0], rgb[1], rgb[2]);
    }
    this.sample.classCounts = counts;
    const shape = this.sample.header.grid.shape;
    const [kept, keptColours] = shape ? exposed(shape, flat, colours)
                                      : [new Uint32Array(0), []];
    this.scene.setVoxels(this.sample.header.grid, kept, keptColours);
    this.drawPoints();
    this.panel.show(st, this.sample);
  }

  drawPoints() {
    const s = this.sample.sections, mode = this.state.points;
    if (mode === 'off' || !s.points_xyz) {
      this.scene.setPoints(null, null);
      return;
    }
    const count = s.points_xyz.length / 3;
    const colours = new Uint8Array(count * 3);
    const [, , z0, , , z1] = this.sample.header.grid.pc_range;
    for (let p = 0; p < count; p++) {
      let rgb;
      if (mode === 'class' && s.points_label) {
        const label = s.points_label[p];
        rgb = label < this.meta.palette.length ? this.meta.palette[label]
                                                : NO_LABEL_COLOUR;
      } else if (mode === 'intensity' && s.points_intensity) {
        // nuScenes intensities crowd the low end: a square root spreads
        // them over the ramp.
        rgb = rampColour(Math.sqrt(s.points_intensity[p] / 255));
      } else {
        rgb = rampColour((s.points_xyz[3 * p + 2] / 100 - z0) / (z1 - z0));
      }
      colours.set(rgb, 3 * p);
    }
    this.scene.setPoints(s.points_xyz, colours, this.state.pointSize);
  }

  hover(event, pinned) {
    if (!this.sample || (this.pinned && !pinned)) return;
    const f = this.scene.pick(event.clientX, event.clientY);
    this.pinned = pinned && f >= 0;
    this.panel.setReadout(f < 0 ? 'hover a voxel' : this.describe(f));
  }

  // What the readout says of voxel `f`.
  describe(f) {
    const {header, sections: s} = this.sample, meta = this.meta;
    const [, Y, Z] = header.grid.shape;
    const i = Math.floor(f / (Y * Z)), j = Math.floor(f / Z) % Y, k = f % Z;
    const [x0, y0, z0] = header.grid.pc_range, v = header.grid.voxel_size;
    const centre = [x0 + (i + 0.5) * v[0], y0 + (j + 0.5) * v[1],
                    z0 + (k + 0.5) * v[2]].map(c => c.toFixed(2));
    const name = label => label === meta.ignore_index ? 'ignored (255)' :
        `${meta.class_names[label]} (${label})`;
    const lines = [`voxel (${i}, ${j}, ${k})`, `centre ${centre.join(', ')} m`];
    if (s.gt) lines.push(`ground truth: ${name(s.gt[f])}`);
    if (s.pred) {
      let text = `prediction: ${name(s.pred[f])}`;
      if (this.sample.probRank && this.sample.probRank[f] >= 0) {
        const p = s.prob[this.sample.probRank[f]] / 255;
        text += `  p = ${p.toFixed(2)}`;
      }
      lines.push(text);
    }
    if (s.errors && s.errors[f] !== NOT_DRAWN) {
      lines.push(`error: ${meta.error_names[s.errors[f]]}`);
    }
    if (s.visibility) {
      const seen = [];
      if (s.visibility[f] & CAMERA_BIT) seen.push('camera');
      if (s.visibility[f] & LIDAR_BIT) seen.push('LiDAR');
      lines.push(`seen by: ${seen.length ? seen.join(', ') : 'neither'}`);
    }
    return lines.join('\n');
  }

  // Resolves once the current state is on screen (for tests: after an
  // action, wait for this, then take the screenshot).
  async drawn() {
    await this.scene.render();
    await new Promise(resolve => requestAnimationFrame(resolve));
  }

  // The actions of the panel (and of the tests).
  setView(view) {
    if (!this.sample.sections[view]) {
      throw new Error(`this sample has no ${view} to show`);
    }
    this.state.view = view;
    this.redraw();
  }
  setMask(mask) { this.state.mask = mask; this.redraw(); }
  setClassVisible(label, on) {
    if (on) this.state.hiddenClasses.delete(label);
    else this.state.hiddenClasses.add(label);
    this.redraw();
  }
  setAllClasses(on) {
    this.state.hiddenClasses = new Set(
        on ? [] : this.meta.class_names.map((_, label) => label));
    this.redraw();
  }
  setErrorVisible(code, on) {
    if (on) this.state.hiddenErrors.delete(code);
    else this.state.hiddenErrors.add(code);
    this.redraw();
  }
  setPoints(mode) {
    this.state.points = mode;
    this.drawPoints();
    this.panel.show(this.state, this.sample);
  }
  setFrusta(on) {
    this.state.frusta = on;
    this.scene.setFrustaVisible(on);
  }
}

// Samples from the server: messages gzip-compressed by HTTP, JPEGs by URL.
const serverSource = {
  async meta() {
    const response = await fetch('api/meta.json');
    if (!response.ok) throw new Error(`meta: HTTP ${response.status}`);
    return response.json();
  },
  async sample(index) {
    const response = await fetch(`api/sample/${index}.bin`);
    if (!response.ok) {
      throw new Error(`HTTP ${response.status}: ${await response.text()}`);
    }
    const buffer = await response.arrayBuffer();
    const header = decodeMessage(buffer).header;
    const imageUrls = header.cameras.map(
        (_, k) => `api/sample/${index}/camera/${k}.jpg`);
    return {buffer, imageUrls};
  },
};

// Samples embedded in an exported page: base64 of the gzip message, JPEGs
// as data URLs.
function embeddedSource(data) {
  return {
    async meta() { return data.meta; },
    async sample(index) {
      const entry = data.samples[index];
      return {buffer: await gunzipBase64(entry.message),
              imageUrls: entry.images};
    },
  };
}

async function start() {
  const embedded = document.getElementById('occ-embedded');
  const source = embedded ? embeddedSource(JSON.parse(embedded.textContent))
                          : serverSource;
  try {
    const meta = await source.meta();
    const viewer = new Viewer(meta, source);
    window.occViewer = viewer;
    await viewer.load(viewer.state.index);
  } catch (err) {
    console.error(err);
    document.body.dataset.state = 'error';
    document.getElementById('status').textContent = err.message;
  }
}

start();
