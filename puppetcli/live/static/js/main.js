// puppetcli live: connect, build the view from the server's hello, then draw every frame.
import { Link } from '/static/js/link.js';
import { View } from '/static/js/scene.js';
import { Hud } from '/static/js/hud.js';
import { Input } from '/static/js/input.js';

const puppet = {
  ready: false, connected: false, frames: 0, lastFrame: null, keys: [], notices: [],
  stopped: null, errors: [],
  latency: () => link.latency(),
  resetLatency: () => { link.samples.length = 0; },
  screenOf: (bone) => view && view.screenOf(bone),
  screenOfWorld: (p) => view && view.screenOfWorld(p),
  pinMarks: () => (view ? view.pins.children.map((m) => m.userData.bone) : []),
};
window.puppet = puppet;
window.addEventListener('error', (e) => puppet.errors.push(String(e.message)));
window.addEventListener('unhandledrejection', (e) => puppet.errors.push(String(e.reason)));

let view = null, hud = null, input = null, frame = null, fresh = false, last = performance.now();
let shapesOf = ''; // the rig the view was built for: a server with another rig reloads the page

function onMessage(msg) {
  if (msg.type === 'hello') hello(msg);
  else if (msg.type === 'frame') { frame = msg; fresh = true; }
  else if (msg.type === 'keys') { hud.keys(msg.keys); puppet.keys = msg.keys; }
  else if (msg.type === 'notice') { hud.notice(msg.level, msg.text); puppet.notices.push(msg.text); }
  else if (msg.type === 'stopped') { hud.end(msg); input.release(false); puppet.stopped = msg; }
}

function hello(msg) {
  const rig = JSON.stringify([msg.rig, msg.bodies, msg.shapes]);
  if (view && rig !== shapesOf) { location.reload(); return; }
  if (!view) { shapesOf = rig; start(msg); }
  input.reset(); // a new connection: nothing gripped, nothing waiting for an ack
  frame = msg.frame; fresh = true;
  hud.keys(msg.keys, false); puppet.keys = msg.keys;
}

function start(hello) {
  view = new View(document.getElementById('view'), hello);
  hud = new Hud(hello, link);
  input = new Input(view, link, hud);
  hud.onKey = () => input.takeKey();
  hud.onRelease = () => input.release();
  requestAnimationFrame(draw);
}

function draw(now) {
  requestAnimationFrame(draw);
  input.poll(Math.min(0.1, (now - last) / 1000));
  if (fresh) view.adapt(now - last);
  last = now;
  input.flush();
  if (!frame) return;
  if (!fresh && !view.moved() && !hud.wanted.length) return; // nothing new to draw
  if (fresh) {
    input.adopt(frame);
    view.update(frame);
    hud.update(frame, { pad: input.pad });
  }
  view.render();
  hud.fillThumbnails(view);
  if (fresh) {
    link.shown();
    fresh = false;
    puppet.frames += 1;
    puppet.lastFrame = frame;
    puppet.ready = true;
  }
}

function onState(up) {
  puppet.connected = up;
  const conn = document.getElementById('conn');
  conn.hidden = up || link.stopped;
  conn.textContent = 'Disconnected: the server may have stopped. Retrying every 2 s…';
  if (hud) hud.connection(up);
}

const link = new Link(onMessage, onState);
