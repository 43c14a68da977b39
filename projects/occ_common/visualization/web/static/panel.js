// The side panel: plain DOM controls whose ids the browser tests use
// (#view-gt, #class-4, #error-1, #points-mode, #next, ...).

function element(tag, props = {}, children = []) {
  const node = document.createElement(tag);
  Object.assign(node, props);
  for (const child of children) node.append(child);
  return node;
}

function swatch(rgb) {
  const node = element('span', {className: 'swatch'});
  node.style.background = `rgb(${rgb.join(',')})`;
  return node;
}

function section(title, ...children) {
  return element('section', {}, [element('h2', {textContent: title}),
                                 ...children]);
}

function checkRow(id, label, rgb, checked, onChange) {
  const box = element('input', {type: 'checkbox', id, checked});
  box.addEventListener('change', () => onChange(box.checked));
  const row = element('label', {className: 'row', htmlFor: id}, [box]);
  if (rgb) row.append(swatch(rgb));
  row.append(element('span', {className: 'name', textContent: label}));
  const count = element('span', {className: 'count'});
  row.append(count);
  return {row, box, count};
}

function select(id, options, onChange) {
  const node = element('select', {id}, options.map(([value, text]) =>
      element('option', {value, textContent: text})));
  node.addEventListener('change', () => onChange(node.value));
  return node;
}

export class Panel {
  // `meta`: the dataset's classes and palettes; `actions`: callbacks.
  constructor(root, meta, actions) {
    this.meta = meta;
    this.actions = actions;
    this.title = element('div', {id: 'title'});
    this.flags = element('div', {id: 'flags'});
    root.append(element('h1', {textContent: meta.title || 'occupancy'}),
                this.title, this.flags);
    this.navigation(root, meta);
    this.views = {};
    const viewRow = element('div', {className: 'views'});
    for (const [view, text] of [['gt', 'ground truth'],
                                ['pred', 'prediction'],
                                ['errors', 'errors']]) {
      const radio = element('input', {type: 'radio', name: 'view',
                                      id: `view-${view}`, value: view});
      radio.addEventListener('change', () => actions.setView(view));
      this.views[view] = radio;
      viewRow.append(element('label', {htmlFor: radio.id}, [radio, text]));
    }
    this.mask = select('mask-mode', [['none', 'all voxels'],
                                     ['camera', 'seen by a camera'],
                                     ['lidar', 'seen by the LiDAR']],
                       value => actions.setMask(value));
    root.append(section('view', viewRow, this.mask));
    this.classRows = meta.class_names.map((name, label) => checkRow(
        `class-${label}`, `${label} ${name}`, meta.palette[label], true,
        on => actions.setClassVisible(label, on)));
    const all = element('button', {id: 'classes-all', textContent: 'all'});
    all.addEventListener('click', () => actions.setAllClasses(true));
    const none = element('button', {id: 'classes-none',
                                    textContent: 'none'});
    none.addEventListener('click', () => actions.setAllClasses(false));
    this.classSection = section('classes', element('div', {}, [all, none]),
                                ...this.classRows.map(r => r.row));
    root.append(this.classSection);
    this.errorRows = meta.error_names.map((name, code) => checkRow(
        `error-${code}`, code === 0 ? 'correct (true positive)' : name,
        meta.error_palette[code], true,
        on => actions.setErrorVisible(code, on)));
    this.errorSection = section('errors', ...this.errorRows.map(r => r.row));
    root.append(this.errorSection);
    this.pointsMode = select('points-mode', [['off', 'no points'],
                                             ['height', 'by height'],
                                             ['intensity', 'by intensity'],
                                             ['class', 'by lidarseg class']],
                             value => actions.setPoints(value));
    const frusta = checkRow('frusta', 'camera frusta and images', null,
                            true, on => actions.setFrusta(on));
    this.frusta = frusta.box;
    this.thumbs = element('div', {id: 'thumbs'});
    root.append(section('sensors', this.pointsMode, frusta.row,
                        this.thumbs));
    this.readout = element('pre', {id: 'readout',
                                   textContent: 'hover a voxel'});
    root.append(section('voxel', this.readout));
  }

  navigation(root, meta) {
    const count = meta.num_samples;
    this.prev = element('button', {id: 'prev', textContent: '\u25c0'});
    this.next = element('button', {id: 'next', textContent: '\u25b6'});
    this.slider = element('input', {id: 'sample-slider', type: 'range',
                                    min: 0, max: Math.max(count - 1, 0),
                                    step: 1});
    this.position = element('span', {id: 'position'});
    this.prev.addEventListener('click', () => this.actions.step(-1));
    this.next.addEventListener('click', () => this.actions.step(1));
    this.slider.addEventListener('change', () => this.actions.load(
        Number(this.slider.value)));
    const nav = element('div', {id: 'navigation'},
                        [this.prev, this.slider, this.next, this.position]);
    if (count <= 1) nav.hidden = true;
    root.append(nav);
  }

  // Reflect the state and the loaded sample.
  show(state, sample) {
    const h = sample.header;
    this.title.textContent = [h.scene_name, h.name].filter(Boolean)
        .join('  \u00b7  ');
    this.flags.replaceChildren(
        ...(h.is_rainy ? [element('span', {className: 'flag rain',
                                           textContent: 'rain'})] : []),
        ...(h.is_night ? [element('span', {className: 'flag night',
                                           textContent: 'night'})] : []),
        ...(!h.is_rainy && !h.is_night ? [element('span', {
          className: 'flag', textContent: 'day, dry'})] : []));
    this.slider.value = state.index;
    this.position.textContent = `${state.index + 1} / ${
        this.meta.num_samples}`;
    const s = sample.sections;
    for (const [view, radio] of Object.entries(this.views)) {
      radio.disabled = !s[view];
      radio.checked = state.view === view;
    }
    this.mask.disabled = !s.visibility;
    // A key frame without labels or prediction has no voxels to list.
    this.classSection.hidden = !s.gt && !s.pred;
    this.mask.value = state.mask;
    this.classRows.forEach((r, label) => {
      r.box.checked = !state.hiddenClasses.has(label);
      const n = sample.classCounts ? sample.classCounts[label] : 0;
      r.count.textContent = n ? String(n) : '';
      r.row.classList.toggle('absent', !n);
      // Empty space is never drawn: no toggle for it.
      r.row.hidden = label === this.meta.empty_label;
    });
    this.errorSection.hidden = !s.errors;
    this.errorRows.forEach((r, code) => {
      r.box.checked = !state.hiddenErrors.has(code);
      r.count.textContent = h.counts.errors ? String(h.counts.errors[code])
                                            : '';
    });
    this.pointsMode.value = state.points;
    this.pointsMode.disabled = !s.points_xyz;
    for (const option of this.pointsMode.options) {
      option.disabled = (option.value === 'class' && !s.points_label) ||
          (option.value === 'intensity' && !s.points_intensity);
    }
    this.frusta.checked = state.frusta;
    this.frusta.disabled = !h.cameras.length;
  }

  setThumbnails(cameras, urls, onPick) {
    this.thumbs.replaceChildren(...urls.map((url, k) => {
      const img = element('img', {src: url, title: cameras[k].name,
                                  alt: cameras[k].name});
      img.addEventListener('click', () => onPick(k));
      return img;
    }));
  }

  setReadout(text) {
    this.readout.textContent = text;
  }
}
