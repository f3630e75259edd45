// The point-cloud viewer of `scanner-sim view RUN_DIR --html` (scanner_sim/render/web_view.py writes its data).
// Reads the JSON in <script id="muls-data">, draws it with three.js (the global THREE of three-orbit.min.js), and
// takes its state from the URL fragment too: #color=depth&zscale=5&mesh=0&trajectory=0&dropouts=0&contours=0.
(function () {
  "use strict";
  const data = JSON.parse(document.getElementById("muls-data").textContent);
  const TYPES = { u1: Uint8Array, u2: Uint16Array, i4: Int32Array, u4: Uint32Array, f4: Float32Array };

  function decode(spec) {
    const text = atob(spec.b64);
    const raw = new Uint8Array(text.length);
    for (let i = 0; i < text.length; i++) raw[i] = text.charCodeAt(i);
    return new TYPES[spec.dtype](raw.buffer);
  }

  function rgbCss(rgb) { return `rgb(${rgb[0]},${rgb[1]},${rgb[2]})`; }

  // Colours are given in sRGB and must reach the screen unchanged.
  THREE.ColorManagement.enabled = false;
  const canvas = document.getElementById("view");
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
  renderer.outputColorSpace = THREE.LinearSRGBColorSpace;
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  renderer.setClearColor(data.background);
  const scene = new THREE.Scene();
  const world = new THREE.Group(); // the vertical exaggeration scales it along z
  scene.add(world);
  scene.add(new THREE.AmbientLight(0xffffff, 0.7));
  const sun = new THREE.DirectionalLight(0xffffff, 0.9);
  sun.position.set(-0.4, -0.6, 1.0);
  scene.add(sun);

  // -- points
  const positions = decode(data.points.positions);
  const count = positions.length / 3;
  const cloud = new THREE.BufferGeometry();
  cloud.setAttribute("position", new THREE.BufferAttribute(positions, 3));
  const colours = new Uint8Array(3 * count);
  cloud.setAttribute("color", new THREE.BufferAttribute(colours, 3, true));
  const pointMaterial = new THREE.PointsMaterial({ size: data.point_size_px, sizeAttenuation: false, vertexColors: true });
  world.add(new THREE.Points(cloud, pointMaterial));
  const fields = {};
  for (const [name, spec] of Object.entries(data.points.fields)) {
    fields[name] = Object.assign({}, spec, { values: decode(spec.values) });
    if (spec.lut) fields[name].lutBytes = decode(spec.lut);
  }

  // -- the scene mesh, faded
  const layers = {};
  if (data.mesh) {
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute("position", new THREE.BufferAttribute(decode(data.mesh.positions), 3));
    geometry.setIndex(new THREE.BufferAttribute(decode(data.mesh.faces), 1));
    geometry.computeVertexNormals();
    layers.mesh = new THREE.Mesh(geometry, new THREE.MeshLambertMaterial({
      color: 0xc8ccd0, transparent: true, opacity: 0.25, side: THREE.DoubleSide, depthWrite: false }));
    world.add(layers.mesh);
  }
  // -- the trajectory
  if (data.trajectory) {
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute("position", new THREE.BufferAttribute(decode(data.trajectory.positions), 3));
    layers.trajectory = new THREE.Line(geometry, new THREE.LineBasicMaterial({ color: 0xffffff }));
    world.add(layers.trajectory);
  }
  // -- the dropouts, by cause, at their beam's nominal footprint
  if (data.dropouts) {
    const cause = decode(data.dropouts.cause);
    const rgb = new Uint8Array(3 * cause.length);
    cause.forEach((c, i) => rgb.set(data.dropouts.colours[c], 3 * i));
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute("position", new THREE.BufferAttribute(decode(data.dropouts.positions), 3));
    geometry.setAttribute("color", new THREE.BufferAttribute(rgb, 3, true));
    layers.dropouts = new THREE.Points(geometry, new THREE.PointsMaterial({
      size: 2.5 * data.point_size_px, sizeAttenuation: false, vertexColors: true }));
    world.add(layers.dropouts);
  }

  // -- camera: obliquely from the south-west and above, fitted to the points
  const half = data.points.half_extent_m;
  const radius = Math.max(Math.hypot(half[0], half[1], half[2]), 0.5);
  const camera = new THREE.PerspectiveCamera(35, 1, radius / 1000, radius * 100);
  camera.up.set(0, 0, 1);
  const look = new THREE.Vector3(-0.55, -1.0, 0.85).normalize();
  camera.position.copy(look.multiplyScalar(radius / Math.sin((35 / 2) * Math.PI / 180) * 0.85));
  const controls = new THREE.OrbitControls(camera, canvas);
  controls.target.set(0, 0, 0);
  controls.update();

  let frames = 0;
  function render() {
    renderer.render(scene, camera);
    frames += 1;
    document.getElementById("frames").textContent = String(frames);
  }
  function resize() {
    renderer.setSize(window.innerWidth, window.innerHeight, false);
    camera.aspect = window.innerWidth / Math.max(window.innerHeight, 1);
    camera.updateProjectionMatrix();
    render();
  }
  controls.addEventListener("change", render);
  window.addEventListener("resize", resize);

  // -- colouring, colour bar and legend
  function colourBy(name) {
    const field = fields[name];
    const v = field.values;
    const legend = document.getElementById("legend");
    legend.replaceChildren();
    if (field.categories) {
      const table = field.categories;
      for (let i = 0; i < count; i++) {
        const entry = table[v[i]];
        colours.set(entry ? entry.rgb : [255, 0, 255], 3 * i);
      }
      for (const entry of Object.values(table)) {
        const row = document.createElement("div");
        row.className = "swatch";
        row.innerHTML = `<span style="background:${rgbCss(entry.rgb)}"></span>`;
        row.append(entry.label);
        legend.append(row);
      }
    } else {
      const lut = field.lutBytes;
      const lo = field.lo, span = field.hi - field.lo || 1;
      const step = field.contour_m && toggles.contours.checked ? field.contour_m : 0;
      for (let i = 0; i < count; i++) {
        const x = v[i];
        if (Number.isNaN(x)) { colours.set([255, 0, 255], 3 * i); continue; }
        const k = Math.round(255 * Math.min(Math.max((x - lo) / span, 0), 1));
        // a contour line: the points within a tenth of an interval above each multiple of it, darkened
        const shade = step && (((x / step) % 1) + 1) % 1 < 0.1 ? 0.45 : 1;
        colours[3 * i] = shade * lut[3 * k]; colours[3 * i + 1] = shade * lut[3 * k + 1];
        colours[3 * i + 2] = shade * lut[3 * k + 2];
      }
      const bar = document.createElement("canvas");
      bar.width = 256; bar.height = 14; bar.className = "bar";
      const g = bar.getContext("2d");
      for (let k = 0; k < 256; k++) {
        g.fillStyle = rgbCss([lut[3 * k], lut[3 * k + 1], lut[3 * k + 2]]);
        g.fillRect(k, 0, 1, 14);
      }
      const ticks = document.createElement("div");
      ticks.className = "ticks";
      for (const t of [field.lo, (field.lo + field.hi) / 2, field.hi]) {
        const s = document.createElement("span");
        s.textContent = Number(t.toPrecision(4)).toString();
        ticks.append(s);
      }
      const title = document.createElement("div");
      title.textContent = field.label + (field.limits ? ` (${field.limits})` : "")
        + (step ? `, contours every ${Number(step.toPrecision(3))} m` : "");
      legend.append(title, bar, ticks);
    }
    cloud.attributes.color.needsUpdate = true;
  }

  // -- state from the controls and the URL fragment
  const select = document.getElementById("colour");
  for (const [name, field] of Object.entries(fields)) {
    const option = document.createElement("option");
    option.value = name; option.textContent = field.label;
    select.append(option);
  }
  const zscale = document.getElementById("zscale");
  const toggles = {};
  for (const name of ["mesh", "trajectory", "dropouts", "contours"]) {
    toggles[name] = document.getElementById(`show-${name}`);
    if (name !== "contours" && !layers[name]) toggles[name].parentElement.style.display = "none";
  }
  function fragment() {
    return Object.fromEntries(new URLSearchParams(location.hash.replace(/^#/, "")));
  }
  function apply() {
    const state = fragment();
    const name = state.color in fields ? state.color : data.default_color;
    select.value = name;
    for (const [layer, box] of Object.entries(toggles)) {
      box.checked = state[layer] !== "0";
      if (layers[layer]) layers[layer].visible = box.checked;
    }
    colourBy(name);
    const k = Number(state.zscale);
    zscale.value = String(Number.isFinite(k) && k > 0 ? k : 1);
    world.scale.set(1, 1, Number(zscale.value));
    document.getElementById("shown-colour").textContent = name;
    render();
  }
  function store() {
    const state = new URLSearchParams({ color: select.value, zscale: zscale.value });
    for (const [layer, box] of Object.entries(toggles)) if (!box.checked) state.set(layer, "0");
    history.replaceState(null, "", "#" + state.toString());
    apply();
  }
  select.addEventListener("change", store);
  zscale.addEventListener("change", store);
  for (const box of Object.values(toggles)) box.addEventListener("change", store);
  window.addEventListener("hashchange", apply);

  document.getElementById("count").textContent = count.toLocaleString("en");
  document.body.dataset.count = String(count);
  resize();
  apply();
  document.body.dataset.ready = "1";
})();
