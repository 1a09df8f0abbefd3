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
};
window.puppet = puppet;
window.addEventListener('error', (e) => puppet.errors.push(String(e.message)));

let view = null, hud = null, input = null, frame = null, fresh = false, last = performance.now();

function onMessage(msg) {
  if (msg.type === 'hello') {
    if (!view) start(msg);
    frame = msg.frame; fresh = true;
    hud.keys(msg.keys); puppet.keys = msg.keys;
  } else if (msg.type === 'frame') {
    frame = msg; fresh = true;
  } else if (msg.type === 'keys') {
    hud.keys(msg.keys); puppet.keys = msg.keys;
  } else if (msg.type === 'notice') {
    hud.notice(msg.level, msg.text); puppet.notices.push(msg.text);
  } else if (msg.type === 'stopped') {
    hud.end(msg); puppet.stopped = msg;
  }
}

function start(hello) {
  view = new View(document.getElementById('view'), hello);
  hud = new Hud(hello, link);
  input = new Input(view, link, hud);
  hud.onKey = () => input.takeKey();
  requestAnimationFrame(draw);
}

function draw(now) {
  requestAnimationFrame(draw);
  input.poll(Math.min(0.1, (now - last) / 1000));
  if (fresh) view.adapt(now - last);
  last = now;
  input.flush();
  if (!frame) return;
  if (!fresh && !view.moved()) return; // nothing new to draw
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

const link = new Link(onMessage, (up) => { puppet.connected = up; });
