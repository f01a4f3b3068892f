// The browser image generator: the village, every soldier drawn from the wire, the stub's keys (seed 002,
// 4.2) and a camera. Connects to a Jack/TTES server's WebSocket port (docs/PROTOCOL.md §2.1). Settings come
// from config.json (written by `ttes web`) and the URL (?ws=ws://127.0.0.1:7001/&soldiers=10&version=2&...).
// window.ttes holds the page's state for tests and benches (fps, soldiers, their screen boxes).
import * as THREE from "three";
import { GLTFLoader } from "three/addons/loaders/GLTFLoader.js";
import { Crowd, FigureSet, SoldierFigure } from "./figure.js";
import { APPEARANCE, Deframer, T, UpdateTable, WEAPON, applyJointUpdates, control, entityRequests, hello, parseMessage } from "./wire.js";

const KEYS = [
  ["1 2 3 4", "posture DEAD / STANDING / KNEELING / PRONE on the current soldier"],
  ["5 6", "weapon DEPLOYED / FIRING"], ["n p", "next / previous soldier"], ["a", "add a soldier near the office"],
  ["A", "add a Jack controlled soldier (reactive behaviours: not implemented)"],
  ["u d", "tethered camera away / towards by 5 m"], ["i j", "rotate the tethered camera ±10°"],
  ["o", "overhead view"], ["b c f v", "view: bird's eye / soldier cam / fly / next view"],
  ["x", "ACTION CAM: the current soldier and the soldiers near him, framed"],
  ["w s", "fly: forward / back 5 m"], ["q e", "fly: turn −10 / +10°"], ["r g", "fly: up / down 2 m"],
  ["← →", "heading −10 / +10°"], ["↑ ↓", "velocity +0.5 / −0.5 m/s"], ["?", "show or hide this list"],
];
const POSTURE_KEYS = { 1: APPEARANCE.DEAD, 2: APPEARANCE.UPRIGHT, 3: APPEARANCE.KNEEL, 4: APPEARANCE.PRONE };
const WEAPON_KEYS = { 5: WEAPON.DEPLOYED, 6: WEAPON.FIRING };
const NAMES = Object.fromEntries(Object.entries(APPEARANCE).map(([k, v]) => [v, k]));
// the stub's views in the order `v` steps through them (client_stub/stub/keys.py), and fly mode's moves
const VIEWS = ["birds-eye", "soldier", "overhead", "fly", "action"];
const FLY_KEYS = { w: [5, 0, 0], s: [-5, 0, 0], q: [0, 0, -10], e: [0, 0, 10], r: [0, 2, 0], g: [0, -2, 0] }; // forward, up, turn

const state = (window.ttes = {
  status: "starting", version: 0, role: "", accepted: false, ready: false, errors: [], log: [],
  soldiers: [], current: 0, fps: 0, frames: 0, updates: 0, view: "soldier", bytesIn: 0,
});
const say = (line) => { state.log.push(line); document.getElementById("line").textContent = line; };

async function settings() {
  let cfg = {};
  try { cfg = await (await fetch("config.json")).json(); } catch { /* no ttes web: URL only */ }
  const q = new URLSearchParams(location.search);
  for (const [k, v] of q) cfg[k] = v;
  return {
    ws: cfg.ws || `ws://${location.hostname || "127.0.0.1"}:7001/`, soldiers: Number(cfg.soldiers ?? 4),
    version: Number(cfg.version ?? 2), role: cfg.role || "controller", token: cfg.token || "",
    motion: cfg.motion || "stand", spacing: Number(cfg.spacing ?? 2.5), view: cfg.view || "soldier",
    entities: cfg.entities || "", // ttes web --replay: where the replayed soldiers are (the wire does not say)
  };
}

// -- scene ------------------------------------------------------------------------------------------------
const renderer = new THREE.WebGLRenderer({ canvas: document.getElementById("view"), antialias: false, preserveDrawingBuffer: true });
const scene = new THREE.Scene();
scene.background = new THREE.Color(0x9db8d6);
const camera = new THREE.PerspectiveCamera(50, 1, 0.1, 2000);
camera.up.set(0, 0, 1);
scene.add(new THREE.HemisphereLight(0xdde8ff, 0x556040, 1.6).translateZ(1));
const sun = new THREE.DirectionalLight(0xffffff, 2.0);
sun.position.set(40, -30, 80);
scene.add(sun);
const materials = {
  soldier: new THREE.MeshLambertMaterial({ color: 0xffffff }), // each soldier's body: his force's colour
  rifle: new THREE.MeshLambertMaterial({ color: 0x303030 }),
};
// uniforms by DIS force id (entities.json; the page's own soldiers are friendly), three looks as the stub's
// replay (client_stub/dis/soldiers.py): friendly blue (the tests look for it), opposing brick red, others slate
const FORCE = { FRIENDLY: 1, OPPOSING: 2 };
const FORCE_COLOURS = { [FORCE.FRIENDLY]: 0x2f6fe0, [FORCE.OPPOSING]: 0xa82a1a, other: 0x8a8a80 };
const forceColour = (force) => FORCE_COLOURS[force] ?? FORCE_COLOURS.other;
const crowd = new Crowd(scene, materials);
const cam = { distance: 9, azimuth: 200, elevation: 18, fly: { position: [0, -60, 20], heading: 0, pitch: -15 }, action: null };
let ground = null; // {x0, y0, step, n, heights}: the village's ground grid, for feet on the terrain
let landmarks = { office: [34, -33], groups: { friendly: [-8, -8] } };

function resize() {
  const w = window.innerWidth, h = window.innerHeight;
  renderer.setSize(w, h, false);
  camera.aspect = w / h;
  camera.updateProjectionMatrix();
}
window.addEventListener("resize", resize);
resize();

async function loadVillage() {
  try { landmarks = await (await fetch("data/village.json")).json(); } catch { /* defaults */ }
  const gltf = await new GLTFLoader().loadAsync("data/village.glb");
  gltf.scene.rotation.x = Math.PI / 2; // glTF's +Y up → the wire's +Z up: (x, y, z) → (x, −z, y)
  // village.glb names no material, so the loader gives glTF's default: fully metallic, which with no environment
  // map reflects no diffuse light (walls facing away from the sun drew black); a matte one, its vertex colours
  const matte = new THREE.MeshStandardMaterial({ vertexColors: true, metalness: 0, roughness: 0.9, flatShading: true });
  gltf.scene.traverse((o) => { if (o.isMesh) o.material = matte; });
  scene.add(gltf.scene);
  const mesh = gltf.scene.getObjectByName("ground");
  if (mesh && mesh.geometry) ground = heightGrid(mesh.geometry.attributes.position);
  gltf.scene.updateMatrixWorld(true);
  const others = [];
  gltf.scene.traverse((o) => { if (o.isMesh && o !== mesh) others.push(o); });
  tops = topGrid(others);
}

// what hides the soldiers from ACTION CAM, as the stub's terrain.height (client_stub/stub/ground.py): the highest
// roof, street or tree under a point (every mesh of the village but the ground); their triangles bucketed by 2 m cell
let tops = null;
function topGrid(meshes, step = 2) {
  const bounds = new THREE.Box3();
  for (const m of meshes) bounds.expandByObject(m);
  const x0 = bounds.min.x, y0 = bounds.min.y, nx = Math.floor((bounds.max.x - x0) / step) + 1, ny = Math.floor((bounds.max.y - y0) / step) + 1;
  const cells = Array.from({ length: nx * ny }, () => []), tris = [], v = new THREE.Vector3();
  const cell = (c, o) => Math.floor((c - o) / step);
  for (const m of meshes) {
    const pos = m.geometry.attributes.position, index = m.geometry.index, n = index ? index.count : pos.count;
    for (let t = 0; t + 2 < n; t += 3) {
      const p = [0, 1, 2].flatMap((k) => v.fromBufferAttribute(pos, index ? index.getX(t + k) : t + k).applyMatrix4(m.matrixWorld).toArray());
      const det = (p[3] - p[0]) * (p[7] - p[1]) - (p[4] - p[1]) * (p[6] - p[0]);
      if (Math.abs(det) < 1e-9) continue; // a wall: no footprint
      const i0 = cell(Math.min(p[0], p[3], p[6]), x0), i1 = cell(Math.max(p[0], p[3], p[6]), x0);
      const j0 = cell(Math.min(p[1], p[4], p[7]), y0), j1 = cell(Math.max(p[1], p[4], p[7]), y0);
      for (let j = j0; j <= j1; j++) for (let i = i0; i <= i1; i++) cells[j * nx + i].push(tris.length);
      tris.push([...p, det]);
    }
  }
  return { x0, y0, step, nx, ny, cells, tris };
}

// the top of the village under x, y: the ground or the highest triangle over it (barycentric in XY, as ground.py)
function topZ(x, y) {
  let h = groundZ(x, y);
  if (!tops) return h;
  const { x0, y0, step, nx, ny, cells, tris } = tops, i = Math.floor((x - x0) / step), j = Math.floor((y - y0) / step);
  if (i < 0 || j < 0 || i >= nx || j >= ny) return h;
  for (const t of cells[j * nx + i]) {
    const [ax, ay, az, bx, by, bz, cx, cy, cz, det] = tris[t], dx = x - ax, dy = y - ay;
    const u = (dx * (cy - ay) - dy * (cx - ax)) / det, w = ((bx - ax) * dy - (by - ay) * dx) / det;
    if (u >= -1e-9 && w >= -1e-9 && u + w <= 1 + 1e-9) h = Math.max(h, az + u * (bz - az) + w * (cz - az));
  }
  return h;
}

// the ground is a regular grid of vertices (client_stub/stub/terrain_gen.py): heights by bilinear lookup
function heightGrid(pos) {
  const xs = new Set(), n = pos.count;
  for (let i = 0; i < n; i++) xs.add(Math.round(pos.getX(i) * 1000));
  const k = xs.size, x0 = Math.min(...xs) / 1000, x1 = Math.max(...xs) / 1000, step = (x1 - x0) / (k - 1);
  const heights = new Float32Array(k * k);
  for (let i = 0; i < n; i++) {
    const ix = Math.round((pos.getX(i) - x0) / step), iy = Math.round((-pos.getZ(i) - x0) / step);
    if (ix >= 0 && iy >= 0 && ix < k && iy < k) heights[iy * k + ix] = pos.getY(i);
  }
  return { x0, step, k, heights };
}

function groundZ(x, y) {
  if (!ground) return 0;
  const { x0, step, k, heights } = ground;
  const fx = Math.min(Math.max((x - x0) / step, 0), k - 1.001), fy = Math.min(Math.max((y - x0) / step, 0), k - 1.001);
  const i = Math.floor(fx), j = Math.floor(fy), u = fx - i, v = fy - j, h = (a, b) => heights[b * k + a];
  return (1 - v) * ((1 - u) * h(i, j) + u * h(i + 1, j)) + v * ((1 - u) * h(i, j + 1) + u * h(i + 1, j + 1));
}

// -- the server ---------------------------------------------------------------------------------------------
const tables = new Map(), figures = new Map(), bySoldier = new Map(), dirty = new Set();
let ws = null, cfg = null, nextId = 1;
const send = (bytes) => { if (ws && ws.readyState === WebSocket.OPEN) ws.send(bytes); };

function connect() {
  ws = new WebSocket(cfg.ws);
  ws.binaryType = "arraybuffer";
  const deframer = new Deframer();
  ws.onopen = () => {
    state.status = "connected";
    send(hello("ttes-web", cfg.role, cfg.version, cfg.token ? { token: cfg.token } : {}));
  };
  ws.onmessage = (ev) => {
    const bytes = new Uint8Array(ev.data);
    state.bytesIn += bytes.length;
    try {
      for (const f of deframer.push(bytes)) handle(f.type, parseMessage(f.type, f.payload));
    } catch (e) {
      state.errors.push(String(e)); say(`error: ${e}`); ws.close();
    }
  };
  ws.onclose = (ev) => lost(ev.code);
}

// the server is gone: forget what it sent, keep our soldiers' requests, try again after 0.5, 1, 2, 4, 8, 8 ... s
// (as the stub and the replay do, PROTOCOL.md §15); READY binds the soldiers again
const BACKOFF = [0.5, 1, 2, 4, 8];
let retries = 0;
function lost(code) {
  const wait = BACKOFF[Math.min(retries++, BACKOFF.length - 1)];
  state.status = `lost (${code}), retrying in ${wait} s`; state.lost = (state.lost || 0) + 1;
  say(`server connection closed (${code}): retrying in ${wait} s`);
  Object.assign(state, { accepted: false, ready: false });
  tables.clear(); figures.clear(); bySoldier.clear(); dirty.clear(); crowd.clear();
  for (const s of state.soldiers) Object.assign(s, { index: -1, table: -1, request: 0, figure: null, posed: 0 });
  setTimeout(connect, wait * 1000);
}

function handle(type, msg) {
  switch (type) {
    case T.ACCEPT:
      retries = 0;
      state.accepted = true; state.version = msg.version; state.role = msg.role || cfg.role;
      say(`accepted by ${msg.name}: protocol version ${msg.version}, role ${state.role}`);
      break;
    case T.UPDATE_TABLE:
      tables.set(msg.table, new UpdateTable(msg));
      send(control(T.REQUEST_FIGURE, { id: nextId++, table: msg.table, meshes: true }));
      break;
    case T.FIGURE:
      figures.set(msg.table, new FigureSet(msg, tables.get(msg.table)));
      state.soldiers.forEach(attach);
      break;
    case T.READY:
      if (!state.ready) {
        state.ready = true;
        if (!cfg.entities) populate(msg.soldiers);
        else if (!state.following) { state.following = true; follow(); }
      }
      break;
    case T.SOLDIER_CREATED: {
      const s = state.soldiers.find((x) => x.request === msg.id);
      if (s) { s.index = msg.index; s.table = msg.table; bind(s); }
      break;
    }
    case T.JOINT_UPDATES: {
      const { table, indices } = applyJointUpdates(tables, msg, state.version);
      state.updates++;
      for (const i of indices) {
        dirty.add(i);
        const s = bySoldier.get(i);
        if (s && s.table < 0) { s.table = table.id; attach(s); } // a followed soldier: his table is the frame's
      }
      break;
    }
    case T.ERROR: state.errors.push(`${msg.code}: ${msg.message}`); say(`server error ${msg.code}: ${msg.message}`); break;
    case T.SOLDIER_REMOVED:
      if (bySoldier.has(msg.index)) { hide(bySoldier.get(msg.index)); say(`soldier removed: ${msg.reason}`); }
      break;
    case T.GOODBYE: say(`goodbye: ${msg.reason}`); break;
    case T.PING: send(control(T.PONG, { nonce: msg.nonce })); break;
    default: break;
  }
}

// our soldiers: the ones READY lists first (the start-up script's), then CREATE_SOLDIER for the rest
function populate(ready) {
  if (state.soldiers.length) { // a new connection: our soldiers again, as they were
    state.soldiers.forEach((s, k) => {
      if (k < ready.length) { [s.index, s.table] = ready[k]; bind(s); } else if (cfg.role !== "observer") create(s);
    });
    return;
  }
  const [gx, gy] = (landmarks.groups && landmarks.groups.friendly) || [-8, -8];
  const n = cfg.role === "observer" ? ready.length : cfg.soldiers; // an observer shows every soldier there is
  const cols = Math.max(1, Math.ceil(Math.sqrt(n)));
  for (let k = 0; k < n; k++) {
    const x = gx + (k % cols) * cfg.spacing, y = gy + Math.floor(k / cols) * cfg.spacing;
    const s = newSoldier([x, y]);
    if (cfg.motion === "walk") s.speed = 1.4;
    if (k < ready.length) { [s.index, s.table] = ready[k]; bind(s); } else create(s);
  }
  state.current = 0;
}

// a soldier drawn nowhere: his instances collapse to a point (slots are not reused)
function hide(s) {
  bySoldier.delete(s.index); s.index = -1; s.speed = 0; s.vel = null;
  if (s.figure) { s.figure.entity.matrix.makeScale(0, 0, 0); s.figure.changed = true; }
}

// ttes web --replay: follow the soldiers the replay drives, placed where entities.json says, every 250 ms
async function follow() {
  let rows = [];
  try { rows = (await (await fetch(cfg.entities)).json()).soldiers; } catch { /* ttes web gone: keep going */ }
  const seen = new Set();
  for (const [index, x, y, , heading, vx, vy, , appearance, weapon, force] of rows) {
    seen.add(index);
    let s = bySoldier.get(index);
    if (!s) {
      s = newSoldier([x, y]);
      s.index = index; s.table = -1;
      bySoldier.set(index, s);
      send(control(T.SUBSCRIBE, { indices: [index] }));
    }
    Object.assign(s, { heading, appearance, weapon, vel: [vx, vy] });
    if (force !== undefined && force !== s.force) { s.force = force; colour(s); }
    s.position = [x, y, groundZ(x, y)];
    s.figure?.place(heading, s.position);
  }
  for (const s of [...bySoldier.values()]) if (!seen.has(s.index)) hide(s);
  state.followed = seen.size;
  setTimeout(follow, 250);
}

function newSoldier(xy) {
  const s = { index: -1, table: -1, request: 0, appearance: APPEARANCE.UPRIGHT, weapon: WEAPON.STOWED, heading: 0, speed: 0,
    position: [xy[0], xy[1], groundZ(xy[0], xy[1])], figure: null, rootZ: null, posed: 0, force: FORCE.FRIENDLY };
  state.soldiers.push(s);
  return s;
}

function create(s) {
  const t = tables.values().next().value;
  s.request = nextId++;
  send(control(T.CREATE_SOLDIER, { id: s.request, figure: t ? t.figure : "DI.fig", weapon: t ? t.weapon : "AK_47.fig", index: null }));
}

function bind(s) {
  bySoldier.set(s.index, s);
  send(control(T.SUBSCRIBE, { indices: [s.index] }));
  if (cfg.role !== "observer") request([s], true); // an observer draws them where it places them
  attach(s);
}

function attach(s) {
  const set = figures.get(s.table);
  if (s.figure || !set) return;
  s.figure = new SoldierFigure(set);
  colour(s);
  s.figure.place(s.heading, s.position);
  crowd.add(s.figure);
  if (tables.get(s.table).soldiers.has(s.index)) dirty.add(s.index);
}

function colour(s) {
  s.colour = forceColour(s.force);
  if (s.figure) { s.figure.colour.setHex(s.colour); s.figure.changed = true; }
}

function velocity(s) {
  const h = THREE.MathUtils.degToRad(s.heading);
  return [s.speed * Math.sin(h), s.speed * Math.cos(h), 0];
}

function request(list, immediate = false) {
  if (cfg.role === "observer") return;
  const rows = list.filter((s) => s.index >= 0).map((s) => ({ index: s.index, appearance: s.appearance, weapon: s.weapon,
    velocity: velocity(s), heading: s.heading, position: s.position, immediate }));
  for (let k = 0; k < rows.length; k += 1000) send(entityRequests(rows.slice(k, k + 1000)));
}

// -- keys (seed 002, 4.2) ---------------------------------------------------------------------------------------
function key(ev) {
  const s = state.soldiers[state.current];
  const k = ev.key;
  if (s && POSTURE_KEYS[k]) { s.appearance = POSTURE_KEYS[k]; request([s]); say(`soldier ${state.current}: ${NAMES[s.appearance]}`); }
  else if (s && WEAPON_KEYS[k]) { s.weapon = WEAPON_KEYS[k]; request([s]); say(`soldier ${state.current}: weapon ${k === "5" ? "DEPLOYED" : "FIRING"}`); }
  else if (s && (k === "ArrowLeft" || k === "ArrowRight")) { s.heading = (s.heading + (k === "ArrowLeft" ? -10 : 10) + 360) % 360; s.figure?.place(s.heading, s.position); request([s]); say(`soldier ${state.current}: heading ${s.heading.toFixed(0)}`); }
  else if (s && (k === "ArrowUp" || k === "ArrowDown")) { s.speed += k === "ArrowUp" ? 0.5 : -0.5; request([s]); say(`soldier ${state.current}: velocity ${s.speed.toFixed(1)} m/s`); }
  else if ((k === "n" || k === "N" || k === "p" || k === "P") && state.soldiers.length) {
    const step = k.toLowerCase() === "n" ? 1 : -1;
    state.current = (state.current + step + state.soldiers.length) % state.soldiers.length;
    say(`current soldier ${state.current}`);
  } else if (k === "a") {
    const [ox, oy] = landmarks.office || [34, -33], n = state.soldiers.length;
    const s2 = newSoldier([ox + (n % 5) * 2.5 - 5, oy - (Math.floor(n / 5) % 4) * 2.5]);
    create(s2); state.current = state.soldiers.length - 1; say(`added soldier ${state.current} near the office building`);
  } else if ("udijo".includes(k.toLowerCase()) && k.length === 1) tether(k.toLowerCase());
  else if (k === "A") say("Jack controlled soldiers (reactive behaviours) are not implemented");
  else if ("bcfvx".includes(k.toLowerCase()) && k.length === 1) view(k.toLowerCase());
  else if (FLY_KEYS[k.toLowerCase()] && state.view === "fly") fly(...FLY_KEYS[k.toLowerCase()]);
  else if (k === "?") document.getElementById("help").hidden = !document.getElementById("help").hidden;
  else return;
  ev.preventDefault();
}

function tether(k) {
  if (state.view !== "soldier" && state.view !== "overhead") state.view = "soldier";
  if (k === "u") cam.distance += 5;
  else if (k === "d") cam.distance = Math.max(2, cam.distance - 5);
  else if (k === "i") cam.azimuth += 10;
  else if (k === "j") cam.azimuth -= 10;
  else state.view = "overhead";
  say(`camera ${state.view}: ${cam.distance} m, azimuth ${cam.azimuth}, elevation ${cam.elevation}`);
}

// b c f v x: as the stub's (client_stub/stub/keys.py); a new ACTION CAM cuts to its framing (no glide)
function view(k) {
  const next = { b: "birds-eye", c: "soldier", f: "fly", x: "action" }[k] || VIEWS[(VIEWS.indexOf(state.view) + 1) % VIEWS.length];
  state.view = next; cam.action = null;
  say(`view: ${state.view}`);
}

function fly(forward, up, turn) {
  const f = cam.fly, h = THREE.MathUtils.degToRad((f.heading = (f.heading + turn + 360) % 360));
  f.position = [f.position[0] + forward * Math.sin(h), f.position[1] + forward * Math.cos(h), f.position[2] + up];
  say(`fly: ${f.position.map((x) => x.toFixed(0)).join(" ")}, heading ${f.heading}`);
}
state.camera = () => ({ view: state.view, position: camera.position.toArray(), fly: cam.fly });

// ACTION CAM (client_stub/stub/camera.py frame_points, clear_pose): from compass 200°, 35° up (else 50°, 65°, 80°:
// the lowest from which roofs and ground do not hide them), as near as keeps the current soldier and every soldier
// within 10 m of him inside the middle 85 % of the picture; eased
const ACTION = { radius: 10, compass: 200, elevations: [35, 50, 65, 80], fill: 0.85, ease: 0.2, cut: 15, nearest: 4 };
const _box = new THREE.Box3();
function actionBox(s) {
  const near = state.soldiers.filter((o) => o.figure && o.index >= 0
    && Math.hypot(o.position[0] - s.position[0], o.position[1] - s.position[1]) <= ACTION.radius);
  const all = new THREE.Box3();
  for (const o of near.length ? near : [s]) { // a figure without surfaces (or none yet): his entity, 1.9 m tall
    const b = o.figure ? crowd.box(o.figure, _box) : _box.makeEmpty();
    if (b.isEmpty()) b.setFromPoints([new THREE.Vector3(...o.position), new THREE.Vector3(o.position[0], o.position[1], o.position[2] + 1.9)]);
    all.union(b);
  }
  return all;
}

function aimAction(s) {
  const target = actionBox(s), mid = target.getCenter(new THREE.Vector3());
  if (!cam.action || cam.action.getCenter(new THREE.Vector3()).distanceTo(mid) > ACTION.cut) cam.action = target.clone();
  else { cam.action.min.lerp(target.min, ACTION.ease); cam.action.max.lerp(target.max, ACTION.ease); }
  const centre = cam.action.getCenter(new THREE.Vector3()), eye = new THREE.Vector3(), sight = new THREE.Vector3();
  for (const elevation of ACTION.elevations) { // the lowest whose line of sight clears roofs and ground (clear_pose)
    frameAction(centre, elevation, eye);
    let clear = true;
    for (let t = 0; t <= 0.9 + 1e-9 && clear; t += 0.05) {
      sight.lerpVectors(eye, centre, t);
      clear = topZ(sight.x, sight.y) < sight.z - 0.3;
    }
    if (clear) break;
  }
  camera.position.copy(eye);
  camera.lookAt(centre);
}

// frame_points: the eye that looks from ACTION.compass, elevation degrees up, at the eased box's centre, as near as
// keeps its corners inside the middle of the picture (each corner's own depth)
function frameAction(centre, elevation, eye) {
  const el = THREE.MathUtils.degToRad(elevation), az = THREE.MathUtils.degToRad(ACTION.compass);
  const back = new THREE.Vector3(Math.cos(el) * Math.sin(az), Math.cos(el) * Math.cos(az), Math.sin(el));
  const right = new THREE.Vector3().crossVectors(back.clone().negate(), camera.up).normalize();
  const up = new THREE.Vector3().crossVectors(right, back.clone().negate());
  const tanY = ACTION.fill * Math.tan(THREE.MathUtils.degToRad(camera.fov) / 2), tanX = camera.aspect * tanY;
  let distance = ACTION.nearest;
  for (let c = 0; c < 8; c++) {
    const q = new THREE.Vector3(c & 1 ? cam.action.max.x : cam.action.min.x, c & 2 ? cam.action.max.y : cam.action.min.y, c & 4 ? cam.action.max.z : cam.action.min.z).sub(centre);
    distance = Math.max(distance, Math.max(Math.abs(q.dot(right)) / tanX, Math.abs(q.dot(up)) / tanY) + q.dot(back));
  }
  return eye.copy(centre).addScaledVector(back, distance);
}

function aimCamera() {
  const s = state.soldiers[state.current];
  if (state.view === "fly") {
    const f = cam.fly, h = THREE.MathUtils.degToRad(f.heading), p = THREE.MathUtils.degToRad(f.pitch);
    camera.position.set(...f.position);
    camera.lookAt(f.position[0] + Math.cos(p) * Math.sin(h), f.position[1] + Math.cos(p) * Math.cos(h), f.position[2] + Math.sin(p));
    return;
  }
  if (state.view === "action" && s) { aimAction(s); return; }
  if (state.view === "birds-eye" || !s) {
    camera.position.set(0, -160, 140); camera.lookAt(0, 0, 0); return;
  }
  const t = new THREE.Vector3(s.position[0], s.position[1], s.position[2] + 0.9);
  const el = THREE.MathUtils.degToRad(state.view === "overhead" ? 85 : cam.elevation);
  const az = THREE.MathUtils.degToRad(cam.azimuth + s.heading);
  camera.position.set(t.x + cam.distance * Math.cos(el) * Math.sin(az), t.y + cam.distance * Math.cos(el) * Math.cos(az), t.z + cam.distance * Math.sin(el));
  camera.lookAt(t);
}

// -- the frame loop ----------------------------------------------------------------------------------------------
const box = new THREE.Box3(), corner = new THREE.Vector3();
function screenBox(s) {
  if (!s.figure) return null;
  crowd.box(s.figure, box);
  let x0 = Infinity, y0 = Infinity, x1 = -Infinity, y1 = -Infinity;
  for (let c = 0; c < 8; c++) {
    corner.set(c & 1 ? box.max.x : box.min.x, c & 2 ? box.max.y : box.min.y, c & 4 ? box.max.z : box.min.z).project(camera);
    const x = (corner.x + 1) / 2 * innerWidth, y = (1 - corner.y) / 2 * innerHeight;
    x0 = Math.min(x0, x); y0 = Math.min(y0, y); x1 = Math.max(x1, x); y1 = Math.max(y1, y);
  }
  return [x0, y0, x1, y1];
}
state.screenBox = (k) => screenBox(state.soldiers[k]);
state.place = (k, [x, y]) => { // tests: soldier k moved to x, y on the ground
  const s = state.soldiers[k];
  s.position = [x, y, groundZ(x, y)]; s.figure?.place(s.heading, s.position); request([s]);
};

let last = performance.now(), windowStart = last, windowFrames = 0;
function frame(now) {
  const dt = Math.min((now - last) / 1000, 0.25);
  last = now;
  for (const s of state.soldiers) {
    if (s.speed || s.vel) {
      const [vx, vy] = s.vel || velocity(s);
      s.position[0] += vx * dt; s.position[1] += vy * dt; s.position[2] = groundZ(s.position[0], s.position[1]);
    }
    if (s.figure && (s.speed || s.vel)) s.figure.place(s.heading, s.position);
  }
  for (const i of dirty) {
    const s = bySoldier.get(i);
    if (!s || !s.figure) continue;
    const p = tables.get(s.table).pose(i);
    if (p) { s.figure.pose(p); s.rootZ = p.figures[0].position[2]; s.posed++; }
  }
  dirty.clear();
  crowd.update();
  aimCamera();
  renderer.render(scene, camera);
  state.frames++; windowFrames++;
  if (now - windowStart >= 1000) { state.fps = (windowFrames * 1000) / (now - windowStart); windowStart = now; windowFrames = 0; }
  document.getElementById("hud").textContent = `${state.status} · v${state.version} · ${state.soldiers.length} soldiers · ${state.fps.toFixed(1)} fps`;
  requestAnimationFrame(frame);
}

document.getElementById("help").textContent = KEYS.map(([k, t]) => `${k.padEnd(8)} ${t}`).join("\n");
window.addEventListener("keydown", key);
cfg = await settings();
state.config = cfg;
state.view = cfg.view;
try { await loadVillage(); } catch (e) { state.errors.push(`village: ${e}`); }
connect();
requestAnimationFrame(frame);
