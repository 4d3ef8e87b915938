// dq_fk_view's page: the robot placed by TF, every frame's axes and name, a panel with the
// selected frame's pose. State for tests and tools: window.dqFkView.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { CSS2DObject, CSS2DRenderer } from 'three/addons/renderers/CSS2DRenderer.js';
import { OBJLoader } from 'three/addons/loaders/OBJLoader.js';
import URDFLoader from 'urdf-loader';

const GREY = new THREE.Color(0xb0b0b0);
const AXIS_LENGTH_M = 0.1;
const PLACEHOLDER_M = 0.05;
const MANY_FRAMES = 40;       // above this many shown frames, only the selected one is named   // the grey box standing for a mesh that could not be loaded
// frames that exist for the DH method only (docs/robot_description.md): hidden by default
const HELPER_FRAME = /^(dh|dh_|dq_fk_dh)\d+$|_dh_z\d*$|_dh_x$|_(dh|dh_|dq_fk_dh)\d+$|^dq_fk_chain\d+_dh\d+$/;

const view = {
  frames: {},          // name -> {parent, position: [x, y, z], quaternion: [x, y, z, w], stale}
  selected: null,
  fixedFrame: null,
  robotLinks: [],      // the URDF's links, placed by TF
  segments: [],        // [parent link, link] of the links drawn as a segment (no visual)
  visuals: [],         // per <visual>: {link, index, kind: mesh|box|cylinder|sphere, uri,
                       //   state: pending|loading|loaded|placeholder|primitive}
  showHelpers: false,  // DH helper frames (dhN, *_dh_z, <tip>_dhN) shown
  showNames: null,     // every shown frame named (null: yes up to MANY_FRAMES frames)
  isHelper: (name) => HELPER_FRAME.test(name),
  visualPoses,         // () -> [{link, index, kind, state, position, quaternion}] in the fixed frame
  labelBoxes,          // () -> [{frame, left, top, right, bottom}] of the visible labels
  robotVersion: 0,
  messages: 0,
  renders: 0,          // pictures drawn (only when something changed)
  arrivals: [],        // the last 1000 frames messages: [newest /tf stamp (ns), arrival (ms)]
  connected: false,
  webgl: true,
  project,             // (frame name) -> {x, y}: where the camera puts its origin, in pixels
  select,
  joints: {},          // the joint panel's sliders (dq_fk_view --joint-panel): name -> value
  mimics: {},          // its mimic joints: name -> value, following their source
  setJoint,            // (name, value) -> moves a slider as the user does; false: no such slider
  resetJoints,         // () -> every slider back to its start
};
window.dqFkView = view;

const container = document.getElementById('view');
const scene = new THREE.Scene();
scene.background = new THREE.Color(0xf4f4f6);
const camera = new THREE.PerspectiveCamera(45, 1, 0.01, 200);
camera.up.set(0, 0, 1);  // ROS: z up
camera.position.set(2.5, -2.5, 1.8);

let renderer = null;
try {
  renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
  container.appendChild(renderer.domElement);
} catch (error) {
  view.webgl = false;  // no WebGL here: frames, labels and the panel still work
  console.warn('dq_fk_view: no WebGL', error);
}
const labelRenderer = new CSS2DRenderer();
labelRenderer.domElement.id = 'labels';
container.appendChild(labelRenderer.domElement);
const controls = new OrbitControls(camera, container);
controls.target.set(0, 0, 0.5);

const grid = new THREE.GridHelper(4, 40, 0x888888, 0xcccccc);
grid.rotation.x = Math.PI / 2;  // on the fixed frame's xy plane
scene.add(grid);
scene.add(new THREE.HemisphereLight(0xffffff, 0x777777, 2.0));
const sun = new THREE.DirectionalLight(0xffffff, 1.5);
sun.position.set(3, -2, 5);
scene.add(sun);

const frameObjects = {};   // name -> {object, axes, label}
const linkGroups = {};     // URDF link -> group of its visuals
let framedCount = 0;       // frames the camera was last fitted to
let userMoved = false;     // once the user orbits or zooms, the camera is theirs
let userSelected = false;  // once the user picks a frame, the selection is theirs
controls.addEventListener('start', () => { userMoved = true; });
// drawn when something changed (poses, the robot, a mesh arriving, the camera, a toggle), not
// every animation frame: a big robot in a software-rendered browser stays responsive, and
// a robot standing still costs nothing
let needsRender = true;
function redraw() { needsRender = true; }
controls.addEventListener('change', redraw);

function resize() {
  const width = container.clientWidth;
  const height = container.clientHeight;
  camera.aspect = width / Math.max(height, 1);
  camera.updateProjectionMatrix();
  if (renderer) renderer.setSize(width, height);
  labelRenderer.setSize(width, height);
  redraw();
}
window.addEventListener('resize', resize);
resize();

function frameObject(name) {
  let entry = frameObjects[name];
  if (entry) return entry;
  const object = new THREE.Object3D();
  object.matrixAutoUpdate = true;
  const axes = new THREE.AxesHelper(AXIS_LENGTH_M);
  object.add(axes);
  const element = document.createElement('div');
  element.className = 'frame-label';
  const text = document.createElement('span');  // moved down when it would overlap another
  text.className = 'frame-label-text';
  text.textContent = name;
  element.appendChild(text);
  element.dataset.frame = name;
  element.addEventListener('pointerdown', (event) => { event.stopPropagation(); select(name); });
  const label = new CSS2DObject(element);
  label.center.set(0, 0.5);  // the name starts at the frame's origin, to its right
  object.add(label);
  scene.add(object);
  entry = frameObjects[name] = { object, axes, label, element, text, stale: null };
  object.visible = view.showHelpers || !view.isHelper(name);
  return entry;
}

function onFrames(message) {
  view.arrivals.push([message.stamp_ns, performance.timeOrigin + performance.now()]);
  if (view.arrivals.length > 1000) view.arrivals.shift();
  view.fixedFrame = message.fixed_frame;
  const seen = new Set();
  for (const [name, parent, x, y, z, qx, qy, qz, qw, stale] of message.frames) {
    seen.add(name);
    const before = view.frames[name];
    if (!before || before.stale !== stale || before.parent !== parent ||
        [x, y, z, qx, qy, qz, qw].some((v, k) => v !== [...before.position,
                                                          ...before.quaternion][k])) {
      redraw();
    }
    view.frames[name] = { parent, position: [x, y, z], quaternion: [qx, qy, qz, qw], stale };
    const entry = frameObject(name);
    entry.object.position.set(x, y, z);
    entry.object.quaternion.set(qx, qy, qz, qw);
    if (entry.stale !== stale) {  // greyed when it stops updating, as RViz does
      if (stale) entry.axes.setColors(GREY, GREY, GREY);
      else entry.axes.setColors(new THREE.Color(0xff0000), new THREE.Color(0x00ff00),
                                new THREE.Color(0x0000ff));
      entry.element.classList.toggle('stale', stale);
      entry.stale = stale;
    }
  }
  for (const name of Object.keys(view.frames)) {
    if (!seen.has(name)) {
      redraw();
      scene.remove(frameObjects[name].object);
      frameObjects[name].element.remove();
      delete frameObjects[name];
      delete view.frames[name];
    }
  }
  stackLabels();
  updateLabels();
  // the server's choice (the deepest frame, or --select) until the user picks one: the tree
  // may still be growing
  if ((!userSelected || !view.frames[view.selected]) && message.select &&
      view.frames[message.select] && view.selected !== message.select) {
    select(message.select, false);
  }
  // fit the camera to the robot while its tree grows (static frames often come first)
  const count = Object.keys(view.frames).length;
  if (!userMoved && count > framedCount) frameTheRobot(count);
  placeRobot();
  updatePanel();
}

function shown(name) {
  return view.showHelpers || !view.isHelper(name);
}

function namesOn() {
  if (view.showNames !== null) return view.showNames;
  return Object.keys(view.frames).filter(shown).length <= MANY_FRAMES;
}

function updateLabels() {
  // a big robot (a humanoid, a mobile manipulator): only the selected frame's name, unless
  // the panel's box asks for all
  const all = namesOn();
  for (const [name, entry] of Object.entries(frameObjects)) {
    entry.label.visible = all || name === view.selected;
  }
  const box = document.getElementById('show-names');
  if (box) box.checked = all;
}

function setShowNames(on) {
  redraw();
  view.showNames = on;
  updateLabels();
}
view.setShowNames = setShowNames;

function stackLabels() {
  // frames at one place (wrist frames, a tool at its flange): their names one under another
  const places = new Map();
  for (const name of Object.keys(view.frames).sort()) {
    if (!shown(name)) continue;
    const key = view.frames[name].position.map((v) => Math.round(v * 1e4)).join(',');
    const k = places.get(key) || 0;
    places.set(key, k + 1);
    frameObjects[name].label.center.set(0, 0.5 - 1.1 * k);
  }
}

function separateLabels() {
  // labels whose boxes overlap on the screen (frames close together): each moved down below
  // the ones placed before it, top to bottom
  const entries = Object.entries(frameObjects).filter(([name, entry]) => shown(name) &&
                                                      entry.label.visible);
  for (const [, entry] of entries) entry.text.style.top = '0px';
  const boxes = entries.map(([name, entry]) => ({ entry, name,
                                                   rect: entry.text.getBoundingClientRect() }))
    .filter((b) => b.rect.width > 0)
    .sort((a, b) => a.rect.top - b.rect.top || a.name.localeCompare(b.name));
  const placed = [];
  for (const box of boxes) {
    let { top } = box.rect;
    const height = box.rect.bottom - box.rect.top;
    let moved = true;
    while (moved) {
      moved = false;
      for (const other of placed) {
        if (box.rect.left < other.right && other.left < box.rect.right &&
            top < other.bottom && other.top < top + height) {
          top = other.bottom + 1;
          moved = true;
        }
      }
    }
    box.entry.text.style.top = `${top - box.rect.top}px`;
    placed.push({ left: box.rect.left, right: box.rect.right, top, bottom: top + height });
  }
}

function labelBoxes() {
  return Object.entries(frameObjects).filter(([name, entry]) => shown(name) &&
                                            entry.label.visible).map(([frame, entry]) => {
    const r = entry.text.getBoundingClientRect();
    return { frame, left: r.left, top: r.top, right: r.right, bottom: r.bottom };
  }).filter((b) => b.right > b.left);
}

function setShowHelpers(on) {
  redraw();
  view.showHelpers = on;
  for (const [name, entry] of Object.entries(frameObjects)) entry.object.visible = shown(name);
  const box = document.getElementById('show-helpers');
  if (box) box.checked = on;
  stackLabels();
  updatePanel(true);
}
view.setShowHelpers = setShowHelpers;

function setRobotVisible(on) {  // for tests and screenshots: the robot's pixels alone
  robotHidden = !on;
  placeRobot();
  redraw();
}
view.setRobotVisible = setRobotVisible;

function drawNow() {  // for tests: draw the scene at once; the picture as a PNG data URL
  if (!renderer) return null;
  renderer.render(scene, camera);
  return renderer.domElement.toDataURL('image/png');
}
view.drawNow = drawNow;

function frameTheRobot(count) {
  const points = Object.values(view.frames).map((f) => new THREE.Vector3(...f.position));
  if (points.length === 0) return;
  const box = new THREE.Box3().setFromPoints(points.concat([new THREE.Vector3()]));
  const centre = box.getCenter(new THREE.Vector3());
  const size = Math.max(box.getSize(new THREE.Vector3()).length(), 0.5);
  controls.target.copy(centre);
  camera.position.copy(centre).add(new THREE.Vector3(1.0, -1.2, 0.8).multiplyScalar(size));
  grid.position.set(centre.x, centre.y, 0);
  grid.scale.setScalar(Math.max(size / 2, 0.5));
  controls.update();
  framedCount = count;
}

function placeholder(material) {
  const box = new THREE.Mesh(new THREE.BoxGeometry(PLACEHOLDER_M, PLACEHOLDER_M, PLACEHOLDER_M),
                             new THREE.MeshPhongMaterial({ color: 0x999999 }));
  box.name = 'placeholder';
  return box;
}

function loadMesh(url, manager, material, done) {
  // STL and COLLADA by urdf-loader's own loader, OBJ by three's OBJLoader
  if (/\.obj$/i.test(url)) {
    new OBJLoader(manager).load(url, (object) => {
      object.traverse((child) => { if (child.isMesh && material) child.material = material; });
      done(object);
    }, null, (error) => done(null, error));
  } else {
    URDFLoader.prototype.defaultMeshLoader(url, manager, material, done);
  }
}

let robotHidden = false;
const visualObjects = [];  // the three.js object of each entry of view.visuals
const segmentMaterial = new THREE.LineBasicMaterial({ color: 0x777777 });
let segments = null;       // links without a visual: a line from the parent link's origin

function onRobot(message) {
  for (const group of Object.values(linkGroups)) scene.remove(group);
  for (const name of Object.keys(linkGroups)) delete linkGroups[name];
  if (segments) scene.remove(segments.object);
  segments = null;
  view.robotLinks = [];
  view.visuals = [];
  visualObjects.length = 0;
  const meshes = message.meshes || {};
  let robot;
  try {
    const loader = new URDFLoader();
    loader.packages = (pkg) => `package://${pkg}`;  // paths stay the URDF's URIs: see meshes
    loader.loadMeshCb = (uri, manager, material, done) => {
      const record = view.visuals.find((v) => v.uri === uri && v.state === 'pending');
      const fallback = (why) => {
        if (record) record.state = 'placeholder';
        if (why) console.warn(`dq_fk_view: mesh ${uri}: ${why}`);
        done(placeholder(material));
      };
      if (record) record.state = 'loading';
      const url = meshes[uri];
      if (!url) { fallback('not served (see the server log)'); return; }
      try {
        loadMesh(url, manager, material, (object, error) => {
          redraw();
          if (error || !object) { fallback(error ? String(error) : 'no model'); return; }
          if (record) record.state = 'loaded';
          done(object);
        });
      } catch (error) {
        fallback(String(error));
      }
    };
    // the visuals in URDF order, noted before the loader asks for their meshes
    const xml = new DOMParser().parseFromString(message.urdf, 'text/xml');
    for (const link of xml.querySelectorAll('robot > link')) {
      [...link.children].filter((n) => n.nodeName === 'visual').forEach((visual, index) => {
        const geometry = visual.querySelector('geometry > *');
        const kind = geometry ? geometry.nodeName : 'none';
        view.visuals.push({ link: link.getAttribute('name'), index, kind,
                            uri: kind === 'mesh' ? geometry.getAttribute('filename') : null,
                            state: kind === 'mesh' ? 'pending' : 'primitive' });
      });
    }
    robot = loader.parse(message.urdf);
  } catch (error) {
    console.warn('dq_fk_view: the robot description could not be read', error);
    view.robotVersion += 1;
    return;
  }
  const withVisual = new Set();
  for (const [name, link] of Object.entries(robot.links)) {
    const group = new THREE.Group();
    group.name = `link:${name}`;
    link.children.filter((child) => child.isURDFVisual).forEach((visual, index) => {
      group.add(visual);  // placed by TF, not by the URDF's joints
      const k = view.visuals.findIndex((v) => v.link === name && v.index === index);
      if (k >= 0) visualObjects[k] = visual;
      withVisual.add(name);
    });
    linkGroups[name] = group;
    scene.add(group);
  }
  // a link without any visual: a thin segment from its parent link's origin, as dq_fk plot
  // (urdf-loader nests each joint in its parent link, its child link in it)
  const pairs = Object.values(robot.joints).map((joint) => {
    const child = joint.children.find((object) => object.isURDFLink);
    return [joint.parent && joint.parent.isURDFLink ? joint.parent.name : null,
            child ? child.name : null];
  }).filter(([parent, child]) => parent && child && !withVisual.has(child));
  if (pairs.length) {
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute('position', new THREE.BufferAttribute(new Float32Array(pairs.length * 6), 3));
    const object = new THREE.LineSegments(geometry, segmentMaterial);
    object.frustumCulled = false;
    segments = { object, pairs };
    scene.add(object);
  }
  view.robotLinks = Object.keys(robot.links);
  view.segments = pairs;
  view.robotVersion += 1;
  placeRobot();
  redraw();
}

function visualPoses() {
  scene.updateMatrixWorld(true);
  return view.visuals.map((v, k) => {
    const object = visualObjects[k];
    const position = new THREE.Vector3();
    const quaternion = new THREE.Quaternion();
    const scale = new THREE.Vector3();
    if (object) object.matrixWorld.decompose(position, quaternion, scale);
    let color = null;  // the colour the first drawn mesh of the visual has
    if (object) {
      object.traverse((child) => {
        if (color === null && child.isMesh && child.material && child.material.color) {
          color = child.material.color.toArray();
        }
      });
    }
    return { link: v.link, index: v.index, kind: v.kind, state: v.state, uri: v.uri, color,
             matrix: object ? object.matrixWorld.toArray() : null,  // column-major, scale in
             placed: Boolean(object && linkGroups[v.link] && linkGroups[v.link].visible),
             position: position.toArray(), quaternion: quaternion.toArray() };
  });
}

function placeRobot() {
  if (segments) {
    const positions = segments.object.geometry.attributes.position;
    segments.pairs.forEach(([parent, child], k) => {
      const a = view.frames[parent] ? view.frames[parent].position : [0, 0, 0];
      const b = view.frames[child] ? view.frames[child].position : a;
      positions.setXYZ(2 * k, ...a);
      positions.setXYZ(2 * k + 1, ...b);
    });
    positions.needsUpdate = true;
  }
  if (segments) segments.object.visible = !robotHidden;
  for (const [name, group] of Object.entries(linkGroups)) {
    const frame = view.frames[name];
    if (robotHidden) {
      group.visible = false;
    } else if (frame) {
      group.visible = true;
      group.position.set(...frame.position);
      group.quaternion.set(...frame.quaternion);
    } else {
      group.visible = name === view.fixedFrame;  // the fixed frame itself sits at the origin
      group.position.set(0, 0, 0);
      group.quaternion.set(0, 0, 0, 1);
    }
  }
}

function select(name, byUser = true) {
  redraw();
  userSelected = userSelected || byUser;
  view.selected = name;
  updateLabels();
  for (const [frame, entry] of Object.entries(frameObjects)) {
    entry.element.classList.toggle('selected', frame === name);
  }
  updatePanel();
}

function fixed(value) {
  const text = value.toFixed(6);
  return text === '-0.000000' ? '0.000000' : text;
}

function updatePanel(force = false) {
  const name = view.selected;
  const frame = name ? view.frames[name] : null;
  document.getElementById('selected-name').textContent = name || '(no frame)';
  document.getElementById('selected-parent').textContent =
    frame ? `parent ${frame.parent}; in ${view.fixedFrame}${frame.stale ? ' (stale)' : ''}` : '';
  document.getElementById('selected-pose').textContent = frame
    ? `position x y z\n${frame.position.map(fixed).join(' ')}\n` +
      `quaternion x y z w\n${frame.quaternion.map(fixed).join(' ')}`
    : '';
  const list = document.getElementById('frame-list');
  const names = Object.keys(view.frames).filter(shown).sort();
  if (force || list.dataset.names !== names.join('\n')) {
    list.replaceChildren(...names.map((frameName) => {
      const item = document.createElement('li');
      item.textContent = frameName;
      item.dataset.frame = frameName;
      item.addEventListener('click', () => select(frameName));
      return item;
    }));
    list.dataset.names = names.join('\n');
  }
  for (const item of list.children) {
    const itemFrame = view.frames[item.dataset.frame];
    item.classList.toggle('selected', item.dataset.frame === name);
    item.classList.toggle('stale', Boolean(itemFrame && itemFrame.stale));
  }
}

function project(name) {
  const entry = frameObjects[name];
  if (!entry) return null;
  const point = entry.object.getWorldPosition(new THREE.Vector3()).project(camera);
  const rect = container.getBoundingClientRect();
  return { x: rect.left + (point.x + 1) / 2 * rect.width,
           y: rect.top + (1 - point.y) / 2 * rect.height };
}

// the joint panel (--joint-panel): a slider per moving joint; the server publishes their
// JointState. Names come from the URDF (anyone's): written with textContent only.
let socket = null;
let panel = null;          // {joints: [[name, lower, upper, start, value]], mimics: [...]}
let sendTimer = null;
const sliders = {};        // name -> {input, value}

function onPanel(spec) {
  const box = document.getElementById('joints');
  box.textContent = '';
  panel = spec || null;
  view.joints = {};
  view.mimics = {};
  for (const name of Object.keys(sliders)) delete sliders[name];
  if (!panel || !panel.joints.length) { box.hidden = true; return; }
  box.hidden = false;
  const title = document.createElement('div');
  title.textContent = `Joints (${panel.joints.length}; published on joint_states)`;
  box.appendChild(title);
  for (const [name, lower, upper, , value] of panel.joints) {
    const row = document.createElement('div');
    row.className = 'joint';
    const label = document.createElement('label');
    const input = document.createElement('input');
    input.type = 'range';
    input.min = String(lower);
    input.max = String(upper);
    input.step = 'any';   // the value as dragged, not snapped to a grid from the minimum
    input.value = String(value);
    input.dataset.joint = name;
    const shown = document.createElement('span');
    shown.className = 'joint-value';
    label.append(name, ' ');
    label.append(shown);
    row.append(label, input);
    box.appendChild(row);
    sliders[name] = { input, shown, lower, upper };
    input.addEventListener('input', () => setJoint(name, Number(input.value)));
    view.joints[name] = value;
    shown.textContent = value.toFixed(3);
  }
  for (const [name, source] of panel.mimics) {
    const row = document.createElement('div');
    row.className = 'mimic';
    const shown = document.createElement('span');
    shown.className = 'mimic-value';
    shown.dataset.joint = name;
    row.append(`${name} (follows ${source}) `, shown);
    box.appendChild(row);
  }
  const reset = document.createElement('button');
  reset.id = 'reset-joints';
  reset.textContent = 'Reset';
  reset.addEventListener('click', resetJoints);
  box.appendChild(reset);
  updateMimics();
}

function mimicValue(name, depth = 0) {
  if (name in view.joints) return view.joints[name];
  const mimic = panel.mimics.find((m) => m[0] === name);
  if (!mimic || depth > 64) return 0;
  return mimic[2] * mimicValue(mimic[1], depth + 1) + mimic[3];
}

function updateMimics() {
  for (const [name] of panel.mimics) {
    view.mimics[name] = mimicValue(name);
    const shown = document.querySelector(`.mimic-value[data-joint="${CSS.escape(name)}"]`);
    if (shown) shown.textContent = view.mimics[name].toFixed(3);
  }
}

function setJoint(name, value) {
  const slider = sliders[name];
  if (!slider || !Number.isFinite(value)) return false;
  const clamped = Math.min(Math.max(value, slider.lower), slider.upper);
  view.joints[name] = clamped;
  slider.input.value = String(clamped);
  slider.shown.textContent = clamped.toFixed(3);
  updateMimics();
  if (sendTimer === null) {  // at most one message per 30 ms, the newest values
    sendTimer = setTimeout(() => {
      sendTimer = null;
      if (socket && socket.readyState === WebSocket.OPEN) {
        socket.send(JSON.stringify({ type: 'joints', positions: view.joints }));
      }
    }, 30);
  }
  return true;
}

function resetJoints() {
  if (!panel) return;
  for (const [name, , , start] of panel.joints) setJoint(name, start);
}

function connect() {
  socket = new WebSocket(`ws://${location.host}/ws`);
  socket.addEventListener('open', () => {
    view.connected = true;
    document.getElementById('status').textContent = 'connected';
    socket.send(JSON.stringify({ type: 'hello' }));
  });
  socket.addEventListener('message', (event) => {
    view.messages += 1;
    const message = JSON.parse(event.data);
    if (message.type === 'frames') onFrames(message);
    else if (message.type === 'robot') {
      onRobot(message);
      onPanel(message.panel);
    }
  });
  socket.addEventListener('close', () => {
    view.connected = false;
    document.getElementById('status').textContent = 'disconnected: retrying...';
    setTimeout(connect, 1000);
  });
}

function render() {
  requestAnimationFrame(render);
  controls.update();
  if (!needsRender) return;
  needsRender = false;
  if (renderer) renderer.render(scene, camera);
  labelRenderer.render(scene, camera);
  separateLabels();
  view.renders += 1;
}

const helperBox = document.getElementById('show-helpers');
if (helperBox) helperBox.addEventListener('change', () => setShowHelpers(helperBox.checked));
const namesBox = document.getElementById('show-names');
if (namesBox) namesBox.addEventListener('change', () => setShowNames(namesBox.checked));

connect();
render();
