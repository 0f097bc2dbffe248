/* pes view: replays one episode record in 3-D with three.js (the global THREE).
 *
 * The scene's data is the JSON of the page's "pes-data" script element, made by scene_data() in
 * src/pes/record/viewer.py (see docs/viewer.md). World axes: x east and y north in the
 * record's metres, z up (altitude, m). window.pesViewer exposes the state and a few controls
 * (setStep, play, pause, setView) for scripts and tests.
 */
(function () {
  "use strict";

  const VEHICLE_SCALE = 5; // vehicles are drawn this many times their body size, to be seen
  const PURSUER_COLOURS = [
    0x1f77b4, 0x2ca02c, 0x9467bd, 0x17becf, 0x8c564b, 0xe377c2, 0xbcbd22, 0x3949ab, 0x00897b,
    0x6d4c41,
  ];
  const EVADER_COLOUR = 0xd62728;
  const PREDICTION_COLOUR = 0xff7f0e;
  const DOWN_COLOUR = 0x8a9099;
  const CAPTURE_COLOUR = 0xd62728;
  const CAPTURED_COLOUR = 0x2a9d3f;
  const BUILDING_COLOUR = 0xc3ccd6;
  const GRID_STEP = 10; // m
  const PLAY_ICON = "M4 2.5v11L13 8z"; // SVG paths of the play button's two faces
  const PAUSE_ICON = "M3.5 3h3v10h-3zM9.5 3h3v10h-3z";

  const api = (window.pesViewer = {
    ready: false,
    error: null,
    step: 0,
    numSteps: 0,
    playing: false,
    speed: 1,
    view: "3d",
    vehicles: 0,
    buildings: 0,
    trails: 0,
    predictions: 0,
    framesRendered: 0,
  });

  function fail(message) {
    api.error = String(message);
    const box = document.getElementById("error");
    box.textContent = "pes view: " + api.error;
    box.hidden = false;
    console.error("pes view: " + api.error);
  }

  window.addEventListener("error", (event) => fail(event.message));

  let data;
  try {
    data = JSON.parse(document.getElementById("pes-data").textContent);
  } catch (exc) {
    fail("the episode data in this page is damaged (" + exc.message + ")");
    return;
  }

  const n = data.num_pursuers;
  const frames = data.frames;
  const last = frames.length - 1;
  const [W, H] = data.arena;
  const L = Math.max(W, H);
  const centre = new THREE.Vector3(W / 2, H / 2, 0);
  const size = data.body_radius * VEHICLE_SCALE; // drawn radius of a vehicle, m
  const maxAltitude = Math.max(...data.altitudes);
  const hasPred = frames.some((f) => f.pred && f.pred.length);
  api.numSteps = last;

  function pursuerColour(v) {
    if (v < PURSUER_COLOURS.length) return new THREE.Color(PURSUER_COLOURS[v]);
    return new THREE.Color().setHSL((0.58 + v * 0.618) % 1, 0.55, 0.45); // golden-angle hues
  }
  const colours = [];
  for (let v = 0; v < n; v++) colours.push(pursuerColour(v));
  colours.push(new THREE.Color(EVADER_COLOUR));
  const names = data.agents.map((a, v) => (v < n ? "P" + v : "E"));
  const hex = (c) => "#" + c.getHexString();

  // --- renderer, scene, camera -----------------------------------------------------------
  THREE.Object3D.DEFAULT_UP.set(0, 0, 1);
  let renderer;
  try {
    renderer = new THREE.WebGLRenderer({
      antialias: true,
      alpha: true,
      preserveDrawingBuffer: true, // so that the canvas can be saved as a picture
    });
  } catch (exc) {
    fail("this page needs WebGL, which this browser does not offer (" + exc.message + ")");
    return;
  }
  renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
  renderer.setSize(window.innerWidth, window.innerHeight);
  renderer.shadowMap.enabled = true;
  renderer.shadowMap.type = THREE.PCFShadowMap;
  renderer.toneMapping = THREE.NeutralToneMapping;
  document.getElementById("scene").appendChild(renderer.domElement);

  const scene = new THREE.Scene();
  const camera = new THREE.PerspectiveCamera(40, window.innerWidth / window.innerHeight, 0.5, 20 * L);
  const controls = new THREE.OrbitControls(camera, renderer.domElement);
  controls.enableDamping = true;
  controls.dampingFactor = 0.12;
  controls.maxPolarAngle = Math.PI / 2 - 0.04; // stay above the ground
  controls.minDistance = 3;
  controls.maxDistance = 6 * L;

  function setView(view) {
    api.view = view;
    const target = new THREE.Vector3(W / 2, H / 2 - (view === "top" ? 0 : 0.04 * L), 0);
    controls.target.copy(target);
    if (view === "top") camera.position.set(W / 2, H / 2 - 0.001 * L, 2.3 * L);
    else camera.position.set(W / 2 - 0.42 * L, H / 2 - 1.3 * L, 1.05 * L);
    controls.update();
    document.getElementById("btn-view").textContent = view === "top" ? "3-D view" : "top view";
  }

  // --- light ------------------------------------------------------------------------------
  scene.add(new THREE.HemisphereLight(0xf2f6ff, 0x8a8270, 2.0));
  const sun = new THREE.DirectionalLight(0xfff6e8, 2.6);
  sun.position.set(W / 2 - 0.7 * L, H / 2 - 0.8 * L, 1.2 * L);
  sun.target.position.copy(centre);
  sun.castShadow = true;
  sun.shadow.mapSize.set(2048, 2048);
  Object.assign(sun.shadow.camera, {
    left: -0.95 * L,
    right: 0.95 * L,
    top: 0.95 * L,
    bottom: -0.95 * L,
    near: 1,
    far: 4 * L,
  });
  sun.shadow.bias = -0.0004;
  sun.shadow.normalBias = 0.03;
  scene.add(sun, sun.target);

  // --- ground, grid, arena ------------------------------------------------------------------
  const outside = new THREE.Mesh(
    new THREE.PlaneGeometry(8 * L, 8 * L),
    new THREE.MeshStandardMaterial({ color: 0xdcd8cd, roughness: 1 }),
  );
  outside.position.set(W / 2, H / 2, -0.05);
  outside.receiveShadow = true;
  scene.add(outside);
  const ground = new THREE.Mesh(
    new THREE.PlaneGeometry(W, H),
    new THREE.MeshStandardMaterial({ color: 0xf6f5f1, roughness: 0.95 }),
  );
  ground.position.set(W / 2, H / 2, 0);
  ground.receiveShadow = true;
  scene.add(ground);

  const gridPoints = [];
  for (let x = 0; x <= W + 1e-6; x += GRID_STEP) gridPoints.push(x, 0, 0.03, x, H, 0.03);
  for (let y = 0; y <= H + 1e-6; y += GRID_STEP) gridPoints.push(0, y, 0.03, W, y, 0.03);
  const gridGeometry = new THREE.BufferGeometry();
  gridGeometry.setAttribute("position", new THREE.Float32BufferAttribute(gridPoints, 3));
  scene.add(
    new THREE.LineSegments(
      gridGeometry,
      new THREE.LineBasicMaterial({ color: 0xaab4bf, transparent: true, opacity: 0.55 }),
    ),
  );
  const border = new THREE.LineLoop(
    new THREE.BufferGeometry().setFromPoints([
      new THREE.Vector3(0, 0, 0.06),
      new THREE.Vector3(W, 0, 0.06),
      new THREE.Vector3(W, H, 0.06),
      new THREE.Vector3(0, H, 0.06),
    ]),
    new THREE.LineBasicMaterial({ color: 0x3e4c59 }),
  );
  scene.add(border);

  // --- buildings -------------------------------------------------------------------------
  const buildingMaterial = new THREE.MeshStandardMaterial({
    color: BUILDING_COLOUR,
    roughness: 0.8,
    metalness: 0.05,
    transparent: true,
  });
  const edgeMaterial = new THREE.LineBasicMaterial({ color: 0x52606d, transparent: true });
  const buildings = new THREE.Group();
  for (const [x0, y0, x1, y1, height] of data.buildings) {
    const box = new THREE.BoxGeometry(x1 - x0, y1 - y0, height);
    const mesh = new THREE.Mesh(box, buildingMaterial);
    mesh.position.set((x0 + x1) / 2, (y0 + y1) / 2, height / 2);
    mesh.castShadow = true;
    mesh.receiveShadow = true;
    mesh.add(new THREE.LineSegments(new THREE.EdgesGeometry(box), edgeMaterial));
    buildings.add(mesh);
  }
  scene.add(buildings);
  api.buildings = buildings.children.length;

  function setGlass(glass) {
    buildingMaterial.opacity = glass ? 0.5 : 1;
    buildingMaterial.depthWrite = !glass;
    edgeMaterial.opacity = glass ? 0.7 : 0.9;
    buildingMaterial.needsUpdate = true;
  }

  // --- vehicles ----------------------------------------------------------------------------
  function labelTexture(text, background) {
    const canvas = document.createElement("canvas");
    canvas.width = 256;
    canvas.height = 96;
    const g = canvas.getContext("2d");
    g.fillStyle = background;
    g.beginPath();
    g.roundRect(4, 4, 248, 88, 28);
    g.fill();
    g.fillStyle = "#ffffff";
    g.font = "bold 54px system-ui, sans-serif";
    g.textAlign = "center";
    g.textBaseline = "middle";
    g.fillText(text, 128, 52);
    const texture = new THREE.CanvasTexture(canvas);
    texture.colorSpace = THREE.SRGBColorSpace;
    return texture;
  }

  function makeVehicle(v) {
    const group = new THREE.Group();
    const body = new THREE.Group(); // tilts with the acceleration
    const paint = new THREE.MeshStandardMaterial({
      color: colours[v],
      roughness: 0.4,
      metalness: 0.15,
    });
    const dark = new THREE.MeshStandardMaterial({ color: 0x2b2f33, roughness: 0.6 });
    const rotorMaterial = new THREE.MeshStandardMaterial({
      color: 0x1b1f23,
      transparent: true,
      opacity: 0.45,
      roughness: 0.5,
    });
    const scale = v === n ? 1.15 : 1; // the evader slightly larger
    const s = size * scale;
    const hull = new THREE.Mesh(new THREE.SphereGeometry(s * 0.42, 20, 12), paint);
    hull.scale.set(1, 1, 0.55);
    body.add(hull);
    for (const angle of [Math.PI / 4, -Math.PI / 4]) {
      const arm = new THREE.Mesh(new THREE.BoxGeometry(2 * s * 0.95, s * 0.12, s * 0.08), dark);
      arm.rotation.z = angle;
      body.add(arm);
    }
    for (const [dx, dy] of [
      [1, 1],
      [1, -1],
      [-1, 1],
      [-1, -1],
    ]) {
      const d = s * 0.67;
      const motor = new THREE.Mesh(new THREE.CylinderGeometry(s * 0.09, s * 0.09, s * 0.16, 10), dark);
      motor.rotation.x = Math.PI / 2;
      motor.position.set(dx * d, dy * d, s * 0.06);
      const rotor = new THREE.Mesh(new THREE.CylinderGeometry(s * 0.38, s * 0.38, s * 0.02, 24), rotorMaterial);
      rotor.rotation.x = Math.PI / 2;
      rotor.position.set(dx * d, dy * d, s * 0.15);
      const ring = new THREE.Mesh(new THREE.TorusGeometry(s * 0.38, s * 0.035, 6, 28), paint);
      ring.position.set(dx * d, dy * d, s * 0.15);
      body.add(motor, rotor, ring);
    }
    body.traverse((o) => {
      o.castShadow = true;
    });
    group.add(body);

    const textures = {
      up: labelTexture(names[v], hex(colours[v])),
      crashed: labelTexture(names[v] + " \u2715", "#6b7280"),
      damaged: labelTexture(names[v] + " \u2013", "#9aa1a9"),
    };
    const label = new THREE.Sprite(
      new THREE.SpriteMaterial({ map: textures.up, depthTest: false, transparent: true }),
    );
    label.scale.set(s * 3.6, s * 1.35, 1);
    label.position.set(0, 0, s * 2.1);
    label.renderOrder = 10;
    group.add(label);
    scene.add(group);
    return { group, body, paint, label, textures, state: "up" };
  }

  const vehicles = [];
  for (let v = 0; v <= n; v++) vehicles.push(makeVehicle(v));
  api.vehicles = vehicles.length;

  function setVehicleState(v, state) {
    const vehicle = vehicles[v];
    if (vehicle.state === state) return;
    vehicle.state = state;
    vehicle.paint.color.set(state === "up" ? colours[v] : new THREE.Color(DOWN_COLOUR));
    vehicle.label.material.map = vehicle.textures[state];
    vehicle.label.material.needsUpdate = true;
  }

  // vertical lines from each vehicle to the ground: altitude at a glance
  const stemPositions = new Float32Array((n + 1) * 6);
  const stemColours = new Float32Array((n + 1) * 6);
  for (let v = 0; v <= n; v++) {
    for (const k of [0, 3]) colours[v].toArray(stemColours, v * 6 + k);
  }
  const stemGeometry = new THREE.BufferGeometry();
  stemGeometry.setAttribute("position", new THREE.BufferAttribute(stemPositions, 3));
  stemGeometry.setAttribute("color", new THREE.BufferAttribute(stemColours, 3));
  const stems = new THREE.LineSegments(
    stemGeometry,
    new THREE.LineBasicMaterial({ vertexColors: true, transparent: true, opacity: 0.45 }),
  );
  stems.frustumCulled = false;
  scene.add(stems);

  // --- trails, prediction, capture radius ---------------------------------------------------
  const lineMaterials = [];
  function lineMaterial(options) {
    const material = new THREE.LineMaterial(
      Object.assign({ linewidth: 3, worldUnits: false, vertexColors: true }, options),
    );
    material.resolution.set(window.innerWidth, window.innerHeight);
    lineMaterials.push(material);
    return material;
  }
  const trails = [];
  for (let v = 0; v <= n; v++) {
    const line = new THREE.Line2(new THREE.LineGeometry(), lineMaterial({ linewidth: v === n ? 3.5 : 3 }));
    line.visible = false;
    line.frustumCulled = false;
    scene.add(line);
    trails.push(line);
  }
  api.trails = trails.length;

  const predLine = new THREE.Line2(
    new THREE.LineGeometry(),
    lineMaterial({
      vertexColors: false,
      color: PREDICTION_COLOUR,
      linewidth: 2.5,
      dashed: true,
      dashSize: 1.6,
      gapSize: 1.0,
    }),
  );
  predLine.visible = false;
  predLine.frustumCulled = false;
  scene.add(predLine);
  const predDots = [];
  const predDotMaterial = new THREE.MeshStandardMaterial({
    color: PREDICTION_COLOUR,
    emissive: PREDICTION_COLOUR,
    emissiveIntensity: 0.35,
  });
  const predDotGeometry = new THREE.SphereGeometry(size * 0.45, 16, 10);

  const capture = new THREE.Group();
  const captureMaterial = new THREE.MeshBasicMaterial({
    color: CAPTURE_COLOUR,
    transparent: true,
    opacity: 0.1,
    side: THREE.DoubleSide,
    depthWrite: false,
  });
  const ringMaterial = new THREE.MeshBasicMaterial({
    color: CAPTURE_COLOUR,
    transparent: true,
    opacity: 0.75,
    side: THREE.DoubleSide,
    depthWrite: false,
  });
  const R = data.capture_radius;
  const columnHeight = maxAltitude + 4;
  const column = new THREE.Mesh(new THREE.CylinderGeometry(R, R, columnHeight, 48, 1, true), captureMaterial);
  column.rotation.x = Math.PI / 2;
  column.position.z = columnHeight / 2;
  const groundRing = new THREE.Mesh(new THREE.RingGeometry(R - 0.12, R + 0.12, 64), ringMaterial);
  groundRing.position.z = 0.08;
  const airRing = new THREE.Mesh(new THREE.RingGeometry(R - 0.1, R + 0.1, 64), ringMaterial);
  airRing.position.z = data.altitudes[n];
  capture.add(column, groundRing, airRing);
  scene.add(capture);

  // --- the state at a (fractional) step -----------------------------------------------------
  const lerp = (a, b, f) => a + (b - a) * f;
  const clampIndex = (k) => Math.max(0, Math.min(last, k));

  function isDown(v, k) {
    return v < n && data.down_step[v] !== null && data.down_step[v] <= k;
  }
  function downState(v, k) {
    if (!isDown(v, k)) return "up";
    return data.crash_step[v] !== null && data.crash_step[v] <= k ? "crashed" : "damaged";
  }
  function position(v, p) {
    const k = Math.floor(p);
    const f = p - k;
    const a = frames[k].pos[v];
    const b = frames[clampIndex(k + 1)].pos[v];
    return [lerp(a[0], b[0], f), lerp(a[1], b[1], f)];
  }
  function acceleration(v, k) {
    if (k <= 0) return [0, 0];
    const a = frames[k - 1].vel[v];
    const b = frames[k].vel[v];
    return [(b[0] - a[0]) / data.dt, (b[1] - a[1]) / data.dt];
  }
  const up = new THREE.Vector3(0, 0, 1);
  const thrust = new THREE.Vector3();
  const maxTilt = Math.tan((35 * Math.PI) / 180);

  function trailLength() {
    const value = document.getElementById("trail").value;
    return value === "all" ? Infinity : Number(value) / data.dt; // seconds to steps
  }

  function updateTrail(v, p, head) {
    const line = trails[v];
    const k = Math.floor(p);
    const length = trailLength();
    let end = k;
    if (isDown(v, k)) end = Math.min(k, data.down_step[v]);
    const start = Math.max(0, Math.floor(end - length));
    const z = data.altitudes[v];
    const points = [];
    for (let j = start; j <= end; j++) points.push(frames[j].pos[v][0], frames[j].pos[v][1], z);
    if (!isDown(v, k) && p > k) points.push(head[0], head[1], z);
    const count = points.length / 3;
    line.visible = length > 0 && count >= 2;
    if (!line.visible) return;
    const fade = new THREE.Color(0xffffff);
    const colour = new THREE.Color();
    const rgb = [];
    for (let i = 0; i < count; i++) {
      colour.copy(fade).lerp(colours[v], 0.25 + (0.75 * i) / (count - 1));
      rgb.push(colour.r, colour.g, colour.b);
    }
    const geometry = new THREE.LineGeometry();
    geometry.setPositions(points);
    geometry.setColors(rgb);
    line.geometry.dispose();
    line.geometry = geometry;
  }

  function updatePrediction(k, evader) {
    const pred = frames[k].pred || [];
    api.predictions = pred.length;
    const z = data.altitudes[n];
    while (predDots.length < pred.length) {
      const dot = new THREE.Mesh(predDotGeometry, predDotMaterial);
      dot.castShadow = true;
      scene.add(dot);
      predDots.push(dot);
    }
    predDots.forEach((dot, i) => {
      dot.visible = i < pred.length;
      if (dot.visible) dot.position.set(pred[i][0], pred[i][1], z);
    });
    predLine.visible = pred.length > 0;
    if (!predLine.visible) return;
    const points = [evader[0], evader[1], z];
    for (const [x, y] of pred) points.push(x, y, z);
    const geometry = new THREE.LineGeometry();
    geometry.setPositions(points);
    predLine.geometry.dispose();
    predLine.geometry = geometry;
    predLine.computeLineDistances();
  }

  function nearCount(k) {
    const e = frames[k].pos[n];
    let near = 0;
    for (let v = 0; v < n; v++) {
      if (isDown(v, k)) continue;
      const q = frames[k].pos[v];
      if (Math.hypot(q[0] - e[0], q[1] - e[1]) <= R) near++;
    }
    return near;
  }

  function updateScene(p) {
    const k = Math.floor(p);
    const f = p - k;
    const heads = [];
    for (let v = 0; v <= n; v++) {
      const vehicle = vehicles[v];
      const state = downState(v, k);
      setVehicleState(v, state);
      const [x, y] = position(v, state === "up" ? p : k);
      heads.push([x, y]);
      const down = state !== "up";
      const z = down ? size * 0.25 : data.altitudes[v];
      vehicle.group.position.set(x, y, z);
      if (down) {
        vehicle.body.quaternion.setFromAxisAngle(new THREE.Vector3(1, 0.4, 0).normalize(), 0.45);
      } else {
        const a0 = acceleration(v, k);
        const a1 = acceleration(v, clampIndex(k + 1));
        let ax = lerp(a0[0], a1[0], f) / 9.81;
        let ay = lerp(a0[1], a1[1], f) / 9.81;
        const tilt = Math.hypot(ax, ay);
        if (tilt > maxTilt) {
          ax *= maxTilt / tilt;
          ay *= maxTilt / tilt;
        }
        thrust.set(ax, ay, 1).normalize();
        vehicle.body.quaternion.setFromUnitVectors(up, thrust);
      }
      stemPositions.set([x, y, 0, x, y, z], v * 6);
      updateTrail(v, state === "up" ? p : k, [x, y]);
    }
    stemGeometry.attributes.position.needsUpdate = true;
    const evader = heads[n];
    capture.position.set(evader[0], evader[1], 0);
    const captured = (k === last && data.outcome.success) || nearCount(k) >= data.capture_count;
    const ringColour = captured ? CAPTURED_COLOUR : CAPTURE_COLOUR;
    captureMaterial.color.set(ringColour);
    ringMaterial.color.set(ringColour);
    updatePrediction(k, evader);
    return heads;
  }

  // --- the readout -------------------------------------------------------------------------
  const tbody = document.querySelector("#readout-table tbody");
  const rows = [];
  for (let v = 0; v <= n; v++) {
    const tr = document.createElement("tr");
    tr.innerHTML =
      '<td><span class="swatch"></span></td><td></td><td class="num"></td>' +
      '<td class="num"></td><td></td>';
    tr.children[0].firstChild.style.background = hex(colours[v]);
    tr.children[1].textContent = names[v] + " " + data.agents[v].id;
    tbody.appendChild(tr);
    rows.push(tr);
  }
  const outcome = data.outcome;
  const outcomeBox = document.getElementById("readout-outcome");
  const seconds = (steps) => (steps * data.dt).toFixed(1) + " s";
  outcomeBox.textContent = outcome.success
    ? "Outcome: captured at step " + outcome.steps + " (" + seconds(outcome.steps) + ")"
    : "Outcome: the evader escaped (" + outcome.steps + " steps, " + seconds(outcome.steps) + ")";
  outcomeBox.textContent += ", " + outcome.crashes + (outcome.crashes === 1 ? " crash" : " crashes");

  function updateReadout(k) {
    const frame = frames[k];
    const e = frame.pos[n];
    document.getElementById("readout-time").textContent =
      "step " + k + " / " + last + "   t = " + frame.t.toFixed(1) + " s";
    for (let v = 0; v <= n; v++) {
      const tr = rows[v];
      const q = frame.pos[v];
      const speed = Math.hypot(frame.vel[v][0], frame.vel[v][1]);
      const state = downState(v, k);
      const gap = Math.hypot(q[0] - e[0], q[1] - e[1]);
      tr.children[2].textContent = v === n ? "" : gap.toFixed(1) + " m";
      tr.children[3].textContent = state === "up" ? speed.toFixed(1) + " m/s" : "";
      let text = v === n ? "evading" : gap <= R ? "within R" : "flying";
      if (state === "crashed") text = "crashed (step " + data.crash_step[v] + ")";
      if (state === "damaged") text = "damaged (step " + data.down_step[v] + ")";
      if (v === n && k === last && outcome.success) text = "captured";
      tr.children[4].textContent = text;
      tr.className = state !== "up" ? "down" : v < n && gap <= R ? "near" : "";
    }
    const alive = frame.alive.filter(Boolean).length;
    document.getElementById("readout-capture").textContent =
      "within R = " + R + " m: " + nearCount(k) + " of " + alive + " flying (" +
      data.capture_count + " needed)";
    outcomeBox.className = k === last ? (outcome.success ? "captured" : "escaped") : "";
    document.getElementById("step-label").textContent =
      "step " + k + " / " + last + " · " + frame.t.toFixed(1) + " s";
    document.getElementById("scrub").value = String(k);
  }

  // --- caption and legend --------------------------------------------------------------------
  document.getElementById("caption-file").textContent = data.title;
  const sc = data.scenario;
  const parts = [n + " pursuers"];
  if (sc.evader_policy) parts.push("evader: " + sc.evader_policy);
  if (sc.disturbance !== undefined) parts.push("disturbance " + (sc.disturbance ? "on" : "off"));
  if (sc.damaged) parts.push(sc.damaged + " damaged");
  if (sc.crash_mode) parts.push("crash_mode " + sc.crash_mode);
  parts.push("dt " + data.dt + " s");
  let captionText = parts.join(" · ");
  if (data.heights_from !== "record") {
    captionText += " · building heights not in the record: " + data.buildings[0]?.[4] + " m each";
  }
  document.getElementById("caption-scenario").textContent = captionText;

  const legend = document.getElementById("legend-list");
  function legendItem(swatchClass, colour, text) {
    const li = document.createElement("li");
    const swatch = document.createElement("span");
    swatch.className = "swatch " + swatchClass;
    swatch.style.background = colour;
    swatch.style.borderColor = colour;
    li.append(swatch, document.createTextNode(text));
    legend.appendChild(li);
  }
  for (let v = 0; v < n; v++) {
    legendItem("", hex(colours[v]), names[v] + ": pursuer " + v + " (" + data.altitudes[v] + " m up)");
  }
  legendItem("", hex(colours[n]), "E: evader (" + data.altitudes[n] + " m up)");
  legendItem("line", "linear-gradient(90deg, #e0e6ee, #1f77b4)", "trail (fades with age)");
  if (hasPred) legendItem("line", "#ff7f0e", "predicted evader path (pred)");
  legendItem("ring", "#d62728", "capture radius " + R + " m (green: enough pursuers inside)");
  legendItem("", "#8a9099", "\u2715 crashed / \u2013 damaged: grey, on the ground");
  legendItem("box", hex(new THREE.Color(BUILDING_COLOUR)), "building (its height)");
  legendItem("line", "#aab4bf", "grid: " + GRID_STEP + " m; vehicles drawn " + VEHICLE_SCALE + "\u00d7 size");

  // --- playback ------------------------------------------------------------------------------
  let playhead = 0;
  let shownStep = -1;
  let needsRender = true;

  function setPlayhead(p) {
    playhead = Math.max(0, Math.min(last, p));
    api.step = Math.floor(playhead + 1e-9);
    updateScene(playhead);
    if (api.step !== shownStep) {
      shownStep = api.step;
      updateReadout(api.step);
    }
    needsRender = true;
  }
  function setPlaying(playing) {
    if (playing && playhead >= last) setPlayhead(0);
    api.playing = playing;
    document.getElementById("btn-play").querySelector("path").setAttribute("d", playing ? PAUSE_ICON : PLAY_ICON);
  }

  function render() {
    renderer.render(scene, camera);
    api.framesRendered++;
    needsRender = false;
  }

  let clock = performance.now();
  const followOffset = new THREE.Vector3();
  function tick(now) {
    const elapsed = Math.min(0.1, (now - clock) / 1000);
    clock = now;
    try {
      if (api.playing) {
        setPlayhead(playhead + (elapsed * api.speed) / data.dt);
        if (playhead >= last) setPlaying(false);
      }
      if (document.getElementById("follow").checked) {
        const [x, y] = position(n, playhead);
        followOffset.set(x, y, data.altitudes[n]).sub(controls.target);
        controls.target.add(followOffset);
        camera.position.add(followOffset);
      }
      if (controls.update()) needsRender = true;
      if (needsRender) render();
    } catch (exc) {
      fail(exc.message);
      return;
    }
    requestAnimationFrame(tick);
  }

  // --- controls ------------------------------------------------------------------------------
  const scrub = document.getElementById("scrub");
  scrub.max = String(last);
  scrub.addEventListener("input", () => {
    setPlaying(false);
    setPlayhead(Number(scrub.value));
  });
  const stepBy = (d) => {
    setPlaying(false);
    setPlayhead(Math.round(playhead) + d);
  };
  document.getElementById("btn-play").addEventListener("click", () => setPlaying(!api.playing));
  document.getElementById("btn-back").addEventListener("click", () => stepBy(-1));
  document.getElementById("btn-forward").addEventListener("click", () => stepBy(1));
  document.getElementById("btn-start").addEventListener("click", () => stepBy(-Infinity));
  document.getElementById("btn-end").addEventListener("click", () => stepBy(Infinity));
  document.getElementById("speed").addEventListener("change", (e) => {
    api.speed = Number(e.target.value);
  });
  document.getElementById("trail").addEventListener("change", () => setPlayhead(playhead));
  document.getElementById("legend-toggle").addEventListener("click", () => {
    legend.hidden = !legend.hidden;
  });
  document.getElementById("glass").addEventListener("change", (e) => {
    setGlass(e.target.checked);
    needsRender = true;
  });
  document.getElementById("btn-view").addEventListener("click", () => {
    setView(api.view === "top" ? "3d" : "top");
    needsRender = true;
  });
  window.addEventListener("keydown", (e) => {
    const typing = e.target.tagName === "INPUT" && !["range", "checkbox"].includes(e.target.type);
    if (typing || e.target.tagName === "SELECT") return;
    const keys = {
      " ": () => setPlaying(!api.playing),
      ArrowLeft: () => stepBy(-1),
      ArrowRight: () => stepBy(1),
      Home: () => stepBy(-Infinity),
      End: () => stepBy(Infinity),
      v: () => document.getElementById("btn-view").click(),
    };
    if (keys[e.key]) {
      keys[e.key]();
      e.preventDefault();
    }
  });
  window.addEventListener("resize", () => {
    renderer.setSize(window.innerWidth, window.innerHeight);
    camera.aspect = window.innerWidth / window.innerHeight;
    camera.updateProjectionMatrix();
    for (const material of lineMaterials) material.resolution.set(window.innerWidth, window.innerHeight);
    needsRender = true;
  });

  // --- for scripts and tests ---------------------------------------------------------------------
  /** Show step k (paused) and draw it now; returns the step shown. */
  api.setStep = (k) => {
    setPlaying(false);
    setPlayhead(Number(k));
    render();
    return api.step;
  };
  // the three.js objects, for poking at the scene by hand (not enumerable: api stays plain data)
  Object.defineProperty(api, "three", { value: { renderer, scene, camera, controls, sun } });
  api.play = () => setPlaying(true);
  api.pause = () => setPlaying(false);
  api.setView = (view) => {
    setView(view);
    render();
  };

  try {
    setGlass(true);
    setView("3d");
    setPlayhead(0);
    render();
    api.ready = true;
  } catch (exc) {
    fail(exc.message);
    return;
  }
  requestAnimationFrame(tick);
})();
