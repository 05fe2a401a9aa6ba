// roarmctl's browser view: places what the page's data says (roarmctl.view/1, written by
// src/roarmctl/viz/web/document.py); every number shown was computed in Python with the library's FK,
// Jacobian and FCL. Text from the data is only ever set as textContent, never parsed as HTML.
(function () {
  'use strict';
  const started = performance.now();
  const D = JSON.parse(document.getElementById('roarm-view-data').textContent);
  const parsed = performance.now();
  const $ = (id) => document.getElementById(id);

  function bytes(b64) {
    const bin = atob(b64 || '');
    const out = new Uint8Array(bin.length);
    for (let i = 0; i < bin.length; i++) out[i] = bin.charCodeAt(i);
    return out;
  }
  const f32 = (b64) => new Float32Array(bytes(b64).buffer);

  const N = D.n;
  const T = f32(D.times), Q = f32(D.q), TCP = f32(D.tcp), SPEED = f32(D.speed), SIGMA = f32(D.sigma_min);
  const CLEAR = f32(D.clearance), POSES = f32(D.poses), COLORS = bytes(D.colors);
  const L = D.links.length, DOF = D.joint_names.length;
  const TORQUE = D.torque ? f32(D.torque) : null, SHARE = D.torque_share ? f32(D.torque_share) : null;
  // per scene item (M): its own distance at each sample (m, -1: not measured), its nearest moving part, whether
  // it is contact the plan means (the object in the jaws, the object on its support at grasp and release)
  const M = D.items.length;
  const ICLEAR = D.item_clearance ? f32(D.item_clearance) : new Float32Array(N * M).fill(-1);
  const IPART = D.item_part ? f32(D.item_part) : new Float32Array(N * M).fill(-1);
  const INTENDED = D.intended ? bytes(D.intended) : new Uint8Array(N * M);
  const IPTS = D.item_points ? f32(D.item_points) : new Float32Array(N * M * 6).fill(NaN);  // (N, M, 6) m
  const PAD = D.padding;
  const ITEM_PALETTE = ['#1f77b4', '#ff7f0e', '#9467bd', '#8c564b', '#e377c2', '#7f7f7f', '#bcbd22', '#17becf'];
  const INTENDED_COLOR = '#1a9850', TIGHT_COLOR = '#d62728';
  const itemColor = (k) => ITEM_PALETTE[k % ITEM_PALETTE.length];
  const tight = (d) => (PAD !== null && PAD !== undefined && d < PAD) || d < 0.005;  // closer than the padding, or 5 mm
  // an item's colour at a sample: green where the distance is contact the plan means, red where it is tight
  const gapColor = (k, d, meant) => (meant ? INTENDED_COLOR : tight(d) ? TIGHT_COLOR : itemColor(k));
  // the smallest clearance that is not intended contact: where "min" goes
  const MINIMUM = (() => {
    let best = { index: -1, item: -1, distance: Infinity };
    for (let i = 0; i < N; i++) {
      for (let k = 0; k < M; k++) {
        const d = ICLEAR[i * M + k];
        if (d >= 0 && !INTENDED[i * M + k] && d < best.distance) best = { index: i, item: k, distance: d };
      }
    }
    return best;
  })();
  const GHOST = D.ghost ? { poses: f32(D.ghost.poses), q: f32(D.ghost.q), error: f32(D.ghost.error), tcp: f32(D.ghost.tcp) } : null;

  // ------------------------------------------------------------------ renderer, camera, lights
  const canvas = $('canvas3d');
  // Software GL (SwiftShader in a headless or GPU-less Chromium, Mesa's llvmpipe): multisampling costs most of a
  // frame (1400 x 900: 2.4 frames/s with it, 7.6 without, on a loaded 2-core machine; bench/bench_view.py), so it
  // is left off there; a GPU does it for free.
  const SOFTWARE_GL = (() => {
    try {
      const gl = document.createElement('canvas').getContext('webgl');
      const ext = gl && gl.getExtension('WEBGL_debug_renderer_info');
      const name = ext ? String(gl.getParameter(ext.UNMASKED_RENDERER_WEBGL)) : '';
      const lose = gl && gl.getExtension('WEBGL_lose_context');
      if (lose) lose.loseContext();
      return /swiftshader|llvmpipe|softpipe|software/i.test(name);
    } catch (e) { return false; }
  })();
  const renderer = new THREE.WebGLRenderer({ canvas: canvas, antialias: !SOFTWARE_GL });
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  const timing = { scriptStart: started, parsed: parsed, context: performance.now() };  // ms since navigation start
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0xf7f8fa);
  scene.add(new THREE.HemisphereLight(0xffffff, 0x8d8d8d, 0.75));
  const sun = new THREE.DirectionalLight(0xffffff, 0.65);
  sun.position.set(1.0, -0.6, 2.0);
  scene.add(sun);

  const lo = new THREE.Vector3().fromArray(D.bounds[0]), hi = new THREE.Vector3().fromArray(D.bounds[1]);
  const centre = lo.clone().add(hi).multiplyScalar(0.5);
  const span = Math.max(hi.clone().sub(lo).length(), 0.05);
  // the camera (static/camera.js): the PNG's views, perspective or orthographic, the wheel's zoom toward the cursor
  const cam = window.roarmCamera(THREE, canvas, D.views || { iso: [26, -38] }, centre, span, (view) => {
    for (const b of document.querySelectorAll('#views button[data-view]')) b.classList.toggle('on', b.dataset.view === view);
    $('orthographic').checked = cam.isOrthographic();
    render();
  });
  const controls = cam.controls;
  function homeCamera() { cam.setView('iso'); }


  // The floor grid at a round spacing (1, 2 or 5 times a power of ten, about 8 to 20 cells over the scene), said
  // in the corner: a scale to read distances by.
  const GRID = (() => {
    const raw = span / 12, p = Math.pow(10, Math.floor(Math.log10(raw)));
    const step = [1, 2, 5, 10].map((m) => m * p).find((v) => v >= raw);
    const cells = 2 * Math.ceil(0.75 * span / step);
    return { spacing: step, size: cells * step, cells: cells };
  })();
  const grid = new THREE.GridHelper(GRID.size, GRID.cells, 0xc8ccd2, 0xe2e5e9);
  grid.rotation.x = Math.PI / 2;  // three.js grids lie in x-z; the world's floor is x-y
  grid.position.set(Math.round(centre.x / GRID.spacing) * GRID.spacing, Math.round(centre.y / GRID.spacing) * GRID.spacing, 0);
  scene.add(grid);
  scene.add(new THREE.AxesHelper(0.05));
  $('grid-scale').textContent = 'grid ' + (GRID.spacing >= 1 ? GRID.spacing + ' m' : +(GRID.spacing * 1000).toPrecision(3) + ' mm');

  function matrixOf(arr, offset, into) {  // 12 floats (3x4, row-major) -> Matrix4 (``into``, else a new one)
    const a = arr, o = offset || 0;
    return (into || new THREE.Matrix4()).set(a[o], a[o + 1], a[o + 2], a[o + 3], a[o + 4], a[o + 5], a[o + 6], a[o + 7],
      a[o + 8], a[o + 9], a[o + 10], a[o + 11], 0, 0, 0, 1);
  }

  // One kind of surface material for everything: each shader program costs a compile (slow in software GL).
  // Opaque surfaces write depth, so a solid's far faces never show over its near ones (drawn see-through without
  // depth, a closed shape looks inside out); they sit a little behind their own plane, so the grid and edges on
  // them never flicker. See-through ones (the checker's shapes over visual meshes, the table on request) draw after
  // every opaque thing, their back faces first.
  // A closed solid wound outward (the document's ``closed``: convex primitives) is drawn opaque without its back
  // faces: software GL fills each pixel once, not twice (a table's bottom under its top: 1.5x the frame rate of
  // pick_place, bench/bench_view.py); see-through, its back faces show.
  function surface(color, opacity, closed) {
    const o = opacity === undefined ? 1 : opacity;
    const m = new THREE.MeshLambertMaterial({ color: color, side: closed && o >= 1 ? THREE.FrontSide : THREE.DoubleSide,
      transparent: o < 1, opacity: o, depthWrite: o >= 1, polygonOffset: o >= 1, polygonOffsetFactor: 1, polygonOffsetUnits: 1 });
    m.userData.closed = !!closed;
    return m;
  }
  function seeThrough(material, on, opacity) {
    material.side = material.userData.closed && !on ? THREE.FrontSide : THREE.DoubleSide;
    material.transparent = on;
    material.opacity = on ? opacity : 1;
    material.depthWrite = !on;
    // not pushed back: over a face in its own plane (an object standing on the table) it always wins the depth
    // test, instead of winning or losing by the view's slope (a colour that changes as the view turns)
    material.polygonOffset = !on;
    material.needsUpdate = true;
  }

  function solid(triangles, color, opacity, edges, closed) {
    const geom = new THREE.BufferGeometry();
    geom.setAttribute('position', new THREE.BufferAttribute(triangles, 3));
    geom.computeVertexNormals();
    const mat = surface(color, opacity, closed);
    const group = new THREE.Group();
    group.add(new THREE.Mesh(geom, mat));
    if (edges) {
      const lines = new THREE.LineSegments(new THREE.EdgesGeometry(geom, 25),
        new THREE.LineBasicMaterial({ color: edges, transparent: true, opacity: 0.6 }));
      group.add(lines);
    }
    return group;
  }

  function placed(object) { object.matrixAutoUpdate = false; scene.add(object); return object; }

  // ------------------------------------------------------------------ robot (the checker's shapes) and ghost
  // Per link: the checker's shapes (opaque, or see-through over the visual meshes where the description has them)
  // and the visual meshes in their colours.
  const HAS_VISUAL = D.links.some((link) => link.visual.length);
  const linkGroups = [], visualGroups = [], collisionGroups = [];
  for (const link of D.links) {
    const g = placed(new THREE.Group());
    const c = link.collision ? solid(f32(link.collision), 0x9aa3ae, HAS_VISUAL ? 0.35 : 1.0, 0x39414b, link.closed) : new THREE.Group();
    g.add(c);
    collisionGroups.push(c);
    const v = new THREE.Group();
    for (const part of link.visual) v.add(solid(f32(part.triangles), part.color || '#b8bec6', 1.0, null));
    g.add(v);
    linkGroups.push(g);
    visualGroups.push(v);
  }
  if (HAS_VISUAL) $('visual-toggle').hidden = false;
  // the stick arm (joint origin to joint origin, as in the PNG): the whole arm of a robot without geometry
  const BONES = f32(D.bone_points), NB = D.bones.length ? BONES.length / (3 * N) : 0;
  const boneGeom = new THREE.BufferGeometry();
  boneGeom.setAttribute('position', new THREE.BufferAttribute(new Float32Array(6 * D.bones.length), 3));
  const skeleton = new THREE.LineSegments(boneGeom, new THREE.LineBasicMaterial({ color: 0x4a5866 }));
  skeleton.visible = L === 0;  // with collision shapes it would only cut across them
  skeleton.frustumCulled = false;
  scene.add(skeleton);
  let ghostGroups = [];
  if (GHOST) {
    ghostGroups = D.links.map((link) => {
      const geom = new THREE.BufferGeometry();
      geom.setAttribute('position', new THREE.BufferAttribute(f32(link.collision || (link.visual[0] || {}).triangles), 3));
      const g = new THREE.LineSegments(new THREE.EdgesGeometry(geom, 25),
        new THREE.LineBasicMaterial({ color: 0xe67e22, transparent: true, opacity: 0.9 }));
      return placed(g);
    });
    $('ghost-toggle').hidden = false;  // (its TCP dot is added with the commanded one below)
    $('ghost-name').textContent = D.ghost.label;
    $('r-ghost-row').hidden = false;
    $('r-ghost-name').textContent = D.ghost.label + ({ run: ' vs planned TCP (the run\'s)', plan: ' vs planned TCP' }[D.ghost.error_source] || ' vs commanded TCP');
  }

  // ------------------------------------------------------------------ scene items
  // Every item is opaque: its colour is its own whatever lies behind it and wherever the camera turns. The table can
  // be made see-through (the toggle) to look at what is under it.
  const TABLE_SEE_THROUGH = 0.35;
  const items = D.items.map((item) => {
    let g;
    if (item.points) {  // a point cloud's occupied cells, each a square a cell wide
      const geom = new THREE.BufferGeometry();
      geom.setAttribute('position', new THREE.BufferAttribute(f32(item.points), 3));
      g = placed(new THREE.Points(geom, new THREE.PointsMaterial({ color: item.color, size: item.point_size })));
    } else {
      g = placed(solid(f32(item.triangles), item.color, 1.0, 0x444444, item.closed));
    }
    g.matrix.copy(matrixOf(item.pose));
    return { name: item.name, role: item.role, group: g, track: item.track ? f32(item.track) : null };
  });
  const tables = items.filter((it) => it.role === 'table' && it.group.children.length);
  if (tables.length) $('table-toggle').hidden = false;
  function setTableSeeThrough(on) {
    for (const t of tables) {
      const mesh = t.group.children[0];
      seeThrough(mesh.material, on, TABLE_SEE_THROUGH);
      mesh.renderOrder = on ? 5 : 0;  // after the arm's see-through shapes
    }
    $('see-through-table').checked = on;
    render();
  }

  // where the run had the objects (a physics run): orange outlines following their tracks
  const ghostItems = GHOST ? (D.ghost.items || []).map((g) => {
    const geom = new THREE.BufferGeometry();
    geom.setAttribute('position', new THREE.BufferAttribute(f32(D.items[g.item].triangles || D.items[g.item].points), 3));
    const outline = placed(new THREE.LineSegments(new THREE.EdgesGeometry(geom, 25),
      new THREE.LineBasicMaterial({ color: 0xe67e22 })));
    return { group: outline, track: f32(g.track) };
  }) : [];

  // ------------------------------------------------------------------ TCP path, marks
  const path = new THREE.Group();
  scene.add(path);
  const lineMaterials = [];
  // A line of ``width`` pixels (three.js's LineMaterial). three.js draws it as one instance of an 8-vertex quad per
  // segment; software GL (SwiftShader) pays per instance what a GPU does not (pick_place's path halved the frame rate:
  // bench/bench_view.py), so the same quads are written out per segment and drawn in one plain draw, by the same shader
  // (its per-instance attributes are ordinary per-vertex ones here).
  function fatLine(positions, colors, width, segments) {
    const instanced = segments ? new THREE.LineSegmentsGeometry() : new THREE.LineGeometry();
    instanced.setPositions(positions);
    instanced.setColors(colors);
    const mat = new THREE.LineMaterial({ linewidth: width, vertexColors: true });
    lineMaterials.push(mat);
    const line = new THREE.Mesh(unrolled(instanced), mat);
    line.frustumCulled = false;  // its 'position' is the quad's corners, not where it lies
    return line;
  }
  function unrolled(instanced) {
    const quad = instanced.index.array, per = instanced.attributes.position.count;
    const k = instanced.attributes.instanceStart.count;
    const geom = new THREE.BufferGeometry();
    for (const [name, attr] of Object.entries(instanced.attributes)) {
      const size = attr.itemSize, out = new Float32Array(k * per * size);
      const perSegment = !!(attr.data && attr.data.isInstancedInterleavedBuffer);
      for (let sgm = 0; sgm < k; sgm++) {
        for (let v = 0; v < per; v++) {
          const i = perSegment ? sgm : v, o = (sgm * per + v) * size;
          out[o] = attr.getX(i);
          if (size > 1) out[o + 1] = attr.getY(i);
          if (size > 2) out[o + 2] = attr.getZ(i);
        }
      }
      geom.setAttribute(name, new THREE.BufferAttribute(out, size));
    }
    const index = new Uint32Array(k * quad.length);
    for (let sgm = 0; sgm < k; sgm++) for (let j = 0; j < quad.length; j++) index[sgm * quad.length + j] = sgm * per + quad[j];
    geom.setIndex(new THREE.BufferAttribute(index, 1));
    instanced.dispose();
    return geom;
  }
  const pathColors = Array.from(COLORS, (c) => c / 255);
  if (N > 1) {
    path.add(fatLine(Array.from(TCP), pathColors, 2.5, false));
    const cart = D.segment_kinds.indexOf('cartesian');
    const pos = [], col = [];
    for (let i = 0; i + 1 < N; i++) {
      if (D.segment[i] !== cart) continue;
      for (const k of [i, i + 1]) {
        pos.push(TCP[3 * k], TCP[3 * k + 1], TCP[3 * k + 2]);
        col.push(pathColors[3 * k], pathColors[3 * k + 1], pathColors[3 * k + 2]);
      }
    }
    if (pos.length) path.add(fatLine(pos, col, 6, true));
  }

  const labels = [];
  function label(text, color, anchor) {
    const div = document.createElement('div');
    div.className = 'label';
    div.textContent = text;
    div.style.color = color;
    $('labels').appendChild(div);
    labels.push({ div: div, anchor: new THREE.Vector3().fromArray(anchor) });
    return { div: div };
  }
  function ball(at, color, radius) {
    const m = new THREE.Mesh(new THREE.SphereGeometry(radius, 16, 12), surface(color));
    m.position.fromArray(at);
    path.add(m);
    return m;
  }
  const tcpAt = (i) => [TCP[3 * i], TCP[3 * i + 1], TCP[3 * i + 2]];
  const mark = Math.max(0.004, 0.012 * span);
  ball(tcpAt(0), 0x2ca02c, 0.6 * mark);
  const end = new THREE.Mesh(new THREE.BoxGeometry(mark, mark, mark), surface(0xd62728));
  end.position.fromArray(tcpAt(N - 1));
  path.add(end);
  for (const e of D.events) {
    ball(e.target, e.color, 0.55 * mark);
    label(e.label, e.color, [e.target[0], e.target[1], e.target[2] + mark]);
  }
  for (const b of D.blends) {
    const m = new THREE.Mesh(new THREE.OctahedronGeometry(0.45 * mark), surface(0xff7f0e));
    m.position.fromArray(tcpAt(b.index));
    path.add(m);
  }
  // Each target the plan names with its miss (the trajectory's table, as the PNG draws it): a cross at the target, a
  // line to the TCP where it came closest, the distance in mm (and the zone it was allowed). Green within its zone,
  // red outside. One line object per colour.
  for (const reached of [true, false]) {
    const pos = [];
    for (const t of D.targets || []) {
      if (t.reached !== reached) continue;
      const [x, y, z] = t.position, c = 0.6 * mark;
      pos.push(x - c, y, z, x + c, y, z, x, y - c, z, x, y + c, z, x, y, z - c, x, y, z + c);
      pos.push(x, y, z, t.closest[0], t.closest[1], t.closest[2]);
      const text = (t.distance * 1000).toFixed(1) + ' mm' + (t.zone > 0 ? ' (zone ' + (t.zone * 1000).toFixed(0) + ')' : '');
      label(text, reached ? '#2ca02c' : '#d62728', [x, y, z - 1.5 * mark]).div.classList.add('miss');
    }
    if (!pos.length) continue;
    const g = new THREE.BufferGeometry();
    g.setAttribute('position', new THREE.Float32BufferAttribute(pos, 3));
    path.add(new THREE.LineSegments(g, new THREE.LineBasicMaterial({ color: reached ? 0x2ca02c : 0xd62728 })));
  }
  if (D.failure && D.failure.target) {
    const x = new THREE.Group();
    for (const s of [1, -1]) {
      const bar = new THREE.Mesh(new THREE.BoxGeometry(3 * mark, 0.5 * mark, 0.5 * mark),
        surface(D.failure.color));
      bar.rotation.y = s * Math.PI / 4;
      x.add(bar);
    }
    x.position.fromArray(D.failure.target);
    path.add(x);
    label('failed: ' + D.failure.label, D.failure.color, [D.failure.target[0], D.failure.target[1], D.failure.target[2] + 2 * mark]);
  }

  // The TCP at the cursor: a round dot of fixed size in pixels, drawn over everything (tests find it on screen).
  const dotCanvas = document.createElement('canvas');
  dotCanvas.width = dotCanvas.height = 64;
  const ctx = dotCanvas.getContext('2d');
  ctx.fillStyle = '#ffffff';
  ctx.beginPath(); ctx.arc(32, 32, 30, 0, 2 * Math.PI); ctx.fill();
  const tcpGeom = new THREE.BufferGeometry();
  tcpGeom.setAttribute('position', new THREE.BufferAttribute(new Float32Array(3), 3));
  const tcpDot = new THREE.Points(tcpGeom, new THREE.PointsMaterial({ color: 0xff00ff, size: 11, sizeAttenuation: false,
    map: new THREE.CanvasTexture(dotCanvas), alphaTest: 0.5, depthTest: false, depthWrite: false, transparent: true }));
  // transparent: drawn in the last pass, after the translucent scene items, so nothing covers it
  tcpDot.renderOrder = 10;
  tcpDot.frustumCulled = false;
  scene.add(tcpDot);
  let ghostDot = null;
  if (GHOST) {  // the measured TCP: a smaller orange dot
    const g = new THREE.BufferGeometry();
    g.setAttribute('position', new THREE.BufferAttribute(new Float32Array(3), 3));
    ghostDot = new THREE.Points(g, new THREE.PointsMaterial({ color: 0xe67e22, size: 8, sizeAttenuation: false,
      map: tcpDot.material.map, alphaTest: 0.5, depthTest: false, depthWrite: false, transparent: true }));
    ghostDot.renderOrder = 9;
    ghostDot.frustumCulled = false;
    scene.add(ghostDot);
  }

  // Every item's closest-point pair at the cursor: a line in 3D with its distance at its middle, drawn over
  // everything, in the item's colour (the strip's and the panel's), green where it is contact the plan means, red
  // where it is tight. One line object for all of them: the pairs shown are packed first, the draw range ends there.
  const gapGeom = new THREE.BufferGeometry();
  gapGeom.setAttribute('position', new THREE.BufferAttribute(new Float32Array(6 * Math.max(M, 1)), 3));
  gapGeom.setAttribute('color', new THREE.BufferAttribute(new Float32Array(6 * Math.max(M, 1)), 3));
  const gapLines = new THREE.LineSegments(gapGeom, new THREE.LineBasicMaterial({ vertexColors: true, depthTest: false, transparent: true }));
  gapLines.renderOrder = 11;
  gapLines.frustumCulled = false;
  scene.add(gapLines);
  const gapLabels = D.items.map((item, k) => {
    const div = document.createElement('div');
    div.className = 'label gap';
    div.dataset.item = String(k);
    $('labels').appendChild(div);
    const anchor = { div: div, anchor: new THREE.Vector3(), dynamic: true, hidden: true };
    labels.push(anchor);
    return anchor;
  });
  let gapsShown = [];  // what the lines show now: [{item, from, to, distance, color}] (for roarmView.gaps)
  function showGaps(i) {
    const pos = gapGeom.attributes.position.array, col = gapGeom.attributes.color.array, colour = new THREE.Color();
    gapsShown = [];
    for (let k = 0; k < M; k++) {
      const d = ICLEAR[i * M + k], o = 6 * (i * M + k), at = gapLabels[k];
      // touching (no pair of closest points), not measured, or its item hidden: no line
      at.hidden = !(d > 0 && Number.isFinite(IPTS[o]) && items[k].group.visible);
      if (at.hidden) continue;
      const c = gapColor(k, d, INTENDED[i * M + k]), e = 6 * gapsShown.length;
      colour.set(c);
      for (let v = 0; v < 6; v++) pos[e + v] = IPTS[o + v];
      col[e] = col[e + 3] = colour.r; col[e + 1] = col[e + 4] = colour.g; col[e + 2] = col[e + 5] = colour.b;
      at.anchor.set((IPTS[o] + IPTS[o + 3]) / 2, (IPTS[o + 1] + IPTS[o + 4]) / 2, (IPTS[o + 2] + IPTS[o + 5]) / 2);
      at.div.textContent = (d * 1000).toFixed(1) + ' mm';
      at.div.style.color = c;
      gapsShown.push({ item: k, from: Array.from(IPTS.subarray(o, o + 3)), to: Array.from(IPTS.subarray(o + 3, o + 6)), distance: d, color: c });
    }
    gapGeom.attributes.position.needsUpdate = true;
    gapGeom.attributes.color.needsUpdate = true;
    gapGeom.setDrawRange(0, 2 * gapsShown.length);
    gapLines.visible = gapsShown.length > 0;
  }

  // ------------------------------------------------------------------ panel
  $('title').textContent = D.title;
  $('subtitle').textContent = D.subtitle;
  $('notes').textContent = (D.notes || []).join(' · ');
  document.title = D.title;
  $('speed-bar').style.background = 'linear-gradient(to right, ' + D.color_stops.join(', ') + ')';
  $('speed-max').textContent = D.speed_max.toFixed(3);
  const marks = [['start', '#2ca02c'], ['end', '#d62728'], ['TCP now', '#ff00ff']];
  if (D.blends.length) marks.push(['blended join (no stop)', '#ff7f0e']);
  if ((D.targets || []).length) marks.push(['target: + and its miss (mm), red outside its zone', '#2ca02c']);
  for (const e of D.events) if (!marks.some((m) => m[0] === e.kind + ' target')) marks.push([e.kind + ' target', e.color]);
  if (GHOST) marks.push([D.ghost.label + ' arm' + (D.ghost.items.length ? ' and objects' : '') + ' (outline)', '#e67e22']);
  if (D.failure) marks.push(['failed target: ' + D.failure.label, D.failure.color]);
  for (const [text, color] of marks) {
    const li = document.createElement('li');
    li.textContent = text;
    li.style.setProperty('--c', color);
    $('marks').appendChild(li);
  }
  const jointCells = D.joint_names.map((name, j) => {
    const tr = document.createElement('tr');
    const cells = [0, 1, 2, 3].map(() => document.createElement('td'));
    cells[0].textContent = name;
    for (const c of cells) tr.appendChild(c);
    $('joints').tBodies[0].appendChild(tr);
    return cells;
  });

  const itemRows = D.items.map((item, k) => {
    const tr = document.createElement('tr');
    const cells = [0, 1, 2].map(() => document.createElement('td'));
    const sw = document.createElement('span');
    sw.className = 'swatch';
    sw.style.setProperty('--c', itemColor(k));
    cells[0].appendChild(sw);
    cells[0].appendChild(document.createTextNode(item.name));
    for (const c of cells) tr.appendChild(c);
    $('item-clearance').tBodies[0].appendChild(tr);
    return cells;
  });
  if (M) { $('item-clearance').hidden = false; $('strip-box').hidden = false; }
  if (MINIMUM.index >= 0) {
    $('go-min').hidden = false;
    $('go-min').textContent = 'min ' + (MINIMUM.distance * 1000).toFixed(1) + ' mm';
  }

  // ------------------------------------------------------------------ time
  const scrub = $('scrub');
  scrub.max = String(Math.max(N - 1, 0));
  let index = 0, playing = false, playTime = 0, lastFrame = 0;

  function sampleAt(t) {  // the last sample at or before t
    let a = 0, b = N - 1;
    if (t >= T[b]) return b;
    while (b - a > 1) { const m = (a + b) >> 1; if (T[m] <= t) a = m; else b = m; }
    return a;
  }

  function fmt(v, digits) { return Number.isFinite(v) ? v.toFixed(digits) : '—'; }

  // A cell is written only when its text or class changes: every write invalidates the panel's layout and paint,
  // which software rendering pays per frame (bench/bench_view.py).
  function put(el, text, cls) {
    if (el.textContent !== text) el.textContent = text;
    if (cls !== undefined && el.className !== cls) el.className = cls;
  }

  function showReadout(i) {
    put($('r-time'), fmt(T[i], 3) + ' s of ' + fmt(D.duration, 3) + ' s (sample ' + (i + 1) + '/' + N + ')');
    put($('clock'), fmt(T[i], 2) + ' / ' + fmt(D.duration, 2) + ' s');
    put($('r-segment'), D.segment_kinds[D.segment[i]] || '—');
    const vmax = D.limits.max_tcp_speed;
    put($('r-speed'), fmt(SPEED[i], 3) + ' m/s' + (vmax ? ' (limit ' + vmax + ')' : ''));
    const margin = D.limits.min_singular_value;
    put($('r-sigma'), fmt(SIGMA[i], 4) + ' m/rad' + (margin ? ' (margin ' + margin + ')' : ''), margin && SIGMA[i] < margin ? 'warn' : '');
    const c = CLEAR[i], item = D.nearest_item[i], part = D.nearest_part[i];
    const meantNearest = c >= 0 && INTENDED[i * M + item];
    put($('r-clearance'), (c < 0 ? 'no scene item' : (c * 1000).toFixed(1) + ' mm: ' + D.parts[part] + ' to ' + D.items[item].name) +
      (meantNearest ? ' (intended contact)' : ''), meantNearest ? 'intended' : c >= 0 && c < 0.005 ? 'warn' : '');
    if (GHOST) put($('r-ghost'), (GHOST.error[i] * 1000).toFixed(1) + ' mm');
    for (let k = 0; k < M; k++) {
      const d = ICLEAR[i * M + k], part = IPART[i * M + k], cells = itemRows[k], meant = INTENDED[i * M + k];
      put(cells[1], d < 0 ? '—' : (d * 1000).toFixed(1) + ' mm', d < 0 ? '' : meant ? 'intended' : tight(d) ? 'warn' : '');
      put(cells[2], d < 0 ? (D.items[k].track ? 'carried' : '') : (D.parts[part] || '') + (meant ? ' (intended)' : ''));
    }
    showGaps(i);
    const at = (N > 1 ? 100 * i / (N - 1) : 0) + '%', cursor = $('strip-cursor');
    if (cursor.style.left !== at) cursor.style.left = at;
    for (let j = 0; j < DOF; j++) {
      const v = Q[i * DOF + j], cells = jointCells[j];
      if (D.joint_units[j] === 'm') { put(cells[1], (v * 1000).toFixed(1) + ' mm'); put(cells[2], ''); }
      else { put(cells[1], v.toFixed(4) + ' rad'); put(cells[2], (v * 180 / Math.PI).toFixed(1) + '°'); }
      // the torque as a share of this joint's own limit (as the PNG's panel); N m where the joint has no limit
      const tau = TORQUE ? TORQUE[i * DOF + j] : NaN, share = SHARE ? SHARE[i * DOF + j] : NaN;
      const unit = D.joint_units[j] === 'm' ? ' N' : ' N m';
      put(cells[3], Number.isFinite(share) ? (Math.round(share) || 0) + ' %' : (Number.isFinite(tau) ? tau.toFixed(2) + unit : '—'),
        Number.isFinite(share) && Math.abs(share) >= 100 ? 'warn' : '');
      const title = Number.isFinite(tau) ? tau.toFixed(3) + unit : '';
      if (cells[3].title !== title) cells[3].title = title;
    }
  }

  function setIndex(i) {
    index = Math.max(0, Math.min(N - 1, Math.round(i)));
    for (let k = 0; k < L; k++) matrixOf(POSES, (index * L + k) * 12, linkGroups[k].matrix);
    for (let k = 0; k < ghostGroups.length; k++) matrixOf(GHOST.poses, (index * L + k) * 12, ghostGroups[k].matrix);
    for (const it of items) if (it.track) matrixOf(it.track, index * 12, it.group.matrix);
    for (const it of ghostItems) matrixOf(it.track, index * 12, it.group.matrix);
    if (skeleton.visible) {  // (hidden, its buffer is not sent to GL every frame)
      const bp = boneGeom.attributes.position;
      D.bones.forEach((pair, k) => {
        for (let e = 0; e < 2; e++) {
          const o = 3 * (index * NB + pair[e]);
          bp.setXYZ(2 * k + e, BONES[o], BONES[o + 1], BONES[o + 2]);
        }
      });
      bp.needsUpdate = true;
    }
    const p = tcpGeom.attributes.position;
    p.setXYZ(0, TCP[3 * index], TCP[3 * index + 1], TCP[3 * index + 2]);
    p.needsUpdate = true;
    if (ghostDot) {
      const g = ghostDot.geometry.attributes.position;
      g.setXYZ(0, GHOST.tcp[3 * index], GHOST.tcp[3 * index + 1], GHOST.tcp[3 * index + 2]);
      g.needsUpdate = true;
    }
    scrub.value = String(index);
    showReadout(index);
    render();
  }

  let live = false;  // no frame before the first sample is placed (each costs in software GL)
  // The labels: a label fixed in the world moves on screen only with the camera, so it is placed again only when the
  // camera moved (or the view's size or the labels' toggle changed: ``labelsStale``); those at the cursor (the gaps'
  // distances) every frame. A label's style is written only when it changes (each write costs a layout).
  let viewW = 1, viewH = 1, labelsStale = true;  // the canvas's CSS size, read on resize (not in a frame: a forced layout)
  const seenView = new THREE.Matrix4(), seenProjection = new THREE.Matrix4(), at = new THREE.Vector3();
  function placeLabel(l, showAll) {
    at.copy(l.anchor).project(cam.camera);
    const visible = !l.hidden && (l.dynamic || showAll) && at.z > -1 && at.z < 1;
    const display = visible ? '' : 'none';
    if (l.div.style.display !== display) l.div.style.display = display;
    if (!visible) return;
    const left = ((at.x + 1) / 2 * viewW).toFixed(1) + 'px', top = ((1 - at.y) / 2 * viewH).toFixed(1) + 'px';
    if (l.div.style.left !== left) l.div.style.left = left;
    if (l.div.style.top !== top) l.div.style.top = top;
  }
  function render() {
    if (!live) return;
    const camera = cam.camera;
    renderer.render(scene, camera);
    const moved = labelsStale || !seenView.equals(camera.matrixWorldInverse) || !seenProjection.equals(camera.projectionMatrix);
    seenView.copy(camera.matrixWorldInverse);
    seenProjection.copy(camera.projectionMatrix);
    labelsStale = false;
    const showAll = $('show-labels').checked;
    for (const l of labels) if (moved || l.dynamic) placeLabel(l, showAll);
  }

  // The clearance strip under the timeline (static/strip.js), drawn once per size, not per frame.
  function drawStrip() {
    if (!M) return;
    window.roarmStrip($('strip'), { n: N, m: M, clearance: ICLEAR, intended: INTENDED, padding: PAD, minimum: MINIMUM,
      names: D.items.map((it) => it.name), color: itemColor, intendedColor: INTENDED_COLOR, tightColor: TIGHT_COLOR });
  }

  function resize() {
    drawStrip();
    const w = canvas.parentElement.clientWidth, h = canvas.parentElement.clientHeight;
    viewW = canvas.clientWidth || w;
    viewH = canvas.clientHeight || h;
    labelsStale = true;
    renderer.setSize(w, h, false);
    cam.setAspect(w / Math.max(h, 1));
    for (const m of lineMaterials) m.resolution.set(w, h);
    render();
  }

  function setPlaying(on) {
    playing = on && N > 1;
    $('play').textContent = playing ? '❚❚' : '▶';
    if (playing) {
      if (index >= N - 1) setIndex(0);
      playTime = T[index];
      lastFrame = performance.now();
      requestAnimationFrame(step);
    }
  }

  function step(now) {
    if (!playing) return;
    playTime += (now - lastFrame) / 1000 * Number($('rate').value);
    lastFrame = now;
    const next = sampleAt(playTime);
    if (next !== index) setIndex(next);  // slowed down, several frames fall on one sample: draw it once
    if (index >= N - 1) { setPlaying(false); return; }
    requestAnimationFrame(step);
  }

  // event and blend ticks above the time slider: a click jumps to that moment
  for (const [list, cls] of [[D.blends, 'blend'], [D.events, 'event']]) {
    for (const e of list) {
      const b = document.createElement('button');
      b.type = 'button';
      b.className = 'tick ' + cls;
      b.dataset.kind = cls === 'blend' ? 'blend' : e.kind;
      b.style.left = (N > 1 ? 100 * e.index / (N - 1) : 0) + '%';
      b.style.setProperty('--c', cls === 'blend' ? '#ff7f0e' : e.color);
      b.title = (cls === 'blend' ? 'blended join' : e.label) + ' at ' + e.time.toFixed(3) + ' s';
      b.addEventListener('click', () => { setPlaying(false); setIndex(e.index); });
      $('ticks').appendChild(b);
    }
  }

  scrub.addEventListener('input', () => { setPlaying(false); setIndex(Number(scrub.value)); });
  function goToMinimum() { if (MINIMUM.index >= 0) { setPlaying(false); setIndex(MINIMUM.index); } }
  $('go-min').addEventListener('click', goToMinimum);
  $('strip').addEventListener('click', (ev) => {
    const r = $('strip').getBoundingClientRect();
    setPlaying(false);
    setIndex((ev.clientX - r.left) / Math.max(r.width, 1) * (N - 1));
  });
  $('play').addEventListener('click', () => setPlaying(!playing));
  $('reset-camera').addEventListener('click', () => { homeCamera(); render(); });
  for (const b of document.querySelectorAll('#views button[data-view]')) b.addEventListener('click', () => cam.setView(b.dataset.view));
  $('orthographic').addEventListener('change', (ev) => cam.setOrthographic(ev.target.checked));
  $('show-collision').addEventListener('change', (ev) => {
    for (const c of collisionGroups) c.visible = ev.target.checked;
    render();
  });
  $('show-visual').addEventListener('change', (ev) => { for (const v of visualGroups) v.visible = ev.target.checked; render(); });
  $('show-path').addEventListener('change', (ev) => { path.visible = ev.target.checked; render(); });
  $('see-through-table').addEventListener('change', (ev) => setTableSeeThrough(ev.target.checked));
  $('show-labels').addEventListener('change', () => { labelsStale = true; render(); });
  $('show-ghost').addEventListener('change', (ev) => {
    for (const g of ghostGroups) g.visible = ev.target.checked;
    for (const g of ghostItems) g.group.visible = ev.target.checked;
    if (ghostDot) ghostDot.visible = ev.target.checked;
    render();
  });
  controls.addEventListener('change', render);
  window.addEventListener('resize', resize);
  document.addEventListener('keydown', (ev) => {
    if (ev.target instanceof HTMLInputElement || ev.target instanceof HTMLSelectElement) return;
    if (ev.key === ' ') { ev.preventDefault(); setPlaying(!playing); }
    else if (ev.key === 'ArrowRight') setIndex(index + 1);
    else if (ev.key === 'ArrowLeft') setIndex(index - 1);
    else if (ev.key === 'm') goToMinimum();
  });

  timing.built = performance.now();  // the scene and the panel made
  homeCamera();
  resize();
  live = true;
  setIndex(0);
  timing.drawn = performance.now();  // the first frame handed to GL (shaders compiled)

  // For scripts and tests: the state of the view, and the camera that drew it (column-major, as three.js keeps it).
  window.roarmView = {
    ready: true,
    timing: Object.assign(timing, { ready: performance.now() }),  // ms since navigation start, per phase
    softwareGL: SOFTWARE_GL,
    // draw calls and triangles of the last frame (three.js counts them), shader programs compiled
    stats: function () {
      return { calls: renderer.info.render.calls, triangles: renderer.info.render.triangles, programs: renderer.info.programs.length };
    },
    data: D,
    setIndex: setIndex,
    setPlaying: setPlaying,
    setTableSeeThrough: setTableSeeThrough,
    minimum: MINIMUM,
    // the closest-point pairs drawn at the cursor: [{item, from, to (world m), distance (m), color}]
    gaps: function () { return gapsShown; },
    setView: cam.setView,
    setOrthographic: cam.setOrthographic,
    zoomAt: cam.zoomAt,
    grid: GRID,
    // show or hide the scene item of this name; false when there is none
    showItem: function (name, visible) {
      const it = items.find((x) => x.name === name);
      if (!it) return false;
      it.group.visible = visible;
      showGaps(index);
      render();
      return true;
    },
    // put the camera at ``position`` looking at ``target`` (world m)
    lookAt: function (position, target) {
      cam.camera.position.fromArray(position);
      controls.target.fromArray(target);
      controls.update();
      render();
    },
    state: function () {
      const rect = canvas.getBoundingClientRect();
      const camera = cam.camera;
      camera.updateMatrixWorld();
      return {
        index: index, time: T[index], playing: playing,
        tcp: tcpAt(index),
        projection: Array.from(camera.projectionMatrix.elements),
        view: Array.from(camera.matrixWorldInverse.elements),
        canvas: { left: rect.left, top: rect.top, width: rect.width, height: rect.height },
      };
    },
  };
})();
