// What the mouse, the keyboard and a 3D mouse (Gamepad API) do: they move the grip's target
// pose and send the commands of docs/live.md.
import * as THREE from 'three';

const DEG = Math.PI / 180;
const DEPTH_STEP = 0.015; // m per wheel notch
const TURN_PER_PIXEL = 0.5 * DEG;
const PAD_DEAD = 0.08, PAD_SPEED = 0.4, PAD_TURN = 90 * DEG; // m/s and rad/s at full deflection
// Which way a 3D mouse's axes 0-2 (and 3-5, about the same axes) point, in camera terms:
// +1 along the camera's right, up and towards-the-viewer axes.  Flip a sign here for a
// device that reports another convention.
const PAD_SIGNS = [1, 1, 1];
const REPEATS = new Set(['ArrowLeft', 'ArrowRight', 'ArrowUp', 'ArrowDown', 'PageUp', 'PageDown', 'q', 'e']);

export class Input {
  constructor(view, link, ui) {
    this.view = view; this.link = link; this.ui = ui;
    this.pos = new THREE.Vector3();
    this.quat = new THREE.Quaternion();
    this.dirty = false;
    this.lastPointerSeq = 0; // seq of the last message that set the target (pointer, grip at a point)
    this.drag = null; // {mode: 'grip'|'touch', plane, offset, x, y}
    this.held = false; // gripping by G (no button held)
    this.frame = null;
    this.bind();
  }

  // A new frame: once the server has applied the page's last target, its target (clamped
  // into the workspace) is the page's.  A G grip that found nothing in reach ends here.
  adopt(frame) {
    this.frame = frame;
    if (!this.dirty && frame.ack >= this.lastPointerSeq) {
      this.pos.fromArray(frame.target.pos);
      const q = frame.target.quat;
      this.quat.set(q[1], q[2], q[3], q[0]);
    }
    if (this.held && !frame.grip && frame.ack >= this.holdSeq) this.held = false;
    const buttons = this.view.controls.mouseButtons;
    buttons.RIGHT = frame.touch ? THREE.MOUSE.ROTATE : THREE.MOUSE.PAN; // touch: left drag is the pointer's
  }

  // A new connection (hello): nothing is held or waits for an ack any more.
  reset() {
    this.drag = null;
    this.held = false;
    this.dirty = false;
    this.lastPointerSeq = 0;
    this.view.controls.enabled = true;
  }

  flush() {
    if (!this.dirty) return;
    const q = this.quat;
    const ok = this.link.send({ type: 'pointer', pos: this.pos.toArray(), quat: [q.w, q.x, q.y, q.z] });
    if (ok) { this.lastPointerSeq = this.link.seq; this.dirty = false; }
  }

  command(message) { this.link.send(message); }

  cameraAxes() {
    const cam = this.view.camera;
    const forward = new THREE.Vector3(); cam.getWorldDirection(forward);
    const up = new THREE.Vector3(0, 1, 0).applyQuaternion(cam.quaternion);
    const right = new THREE.Vector3(1, 0, 0).applyQuaternion(cam.quaternion);
    return { forward, up, right };
  }

  planeThrough(point) {
    return new THREE.Plane().setFromNormalAndCoplanarPoint(this.cameraAxes().forward, point);
  }

  moveBy(delta) { this.pos.add(delta); this.dirty = true; if (this.drag) this.drag.plane = this.planeThrough(this.pos); }

  turn(axis, angle) {
    this.quat.premultiply(new THREE.Quaternion().setFromAxisAngle(axis.normalize(), angle));
    this.dirty = true;
  }

  bind() {
    const area = document.getElementById('view');
    area.addEventListener('pointerdown', (e) => this.down(e), { capture: true });
    window.addEventListener('pointermove', (e) => this.move(e));
    window.addEventListener('pointerup', (e) => this.up(e));
    area.addEventListener('wheel', (e) => this.wheel(e), { capture: true, passive: false });
    window.addEventListener('keydown', (e) => this.key(e));
  }

  down(e) {
    if (e.button !== 0 || this.ui.stopped) return;
    const touch = this.frame && this.frame.touch;
    const hit = touch ? null : this.view.pick(e.clientX, e.clientY);
    if (!touch && !hit) return; // the camera's drag
    e.stopPropagation();
    e.preventDefault();
    if (hit && e.altKey) { this.togglePin(hit, e.shiftKey); return; } // Alt+click: pin / unpin
    if (hit) {
      if (this.held) { this.command({ type: 'release' }); this.held = false; }
      this.pos.copy(hit.point);
      const grip = { type: 'grip', bone: hit.bone, point: hit.point.toArray() };
      if (e.shiftKey) grip.position_only = false; // Shift+press: hold the whole bone, to turn it
      this.command(grip);
      this.lastPointerSeq = this.link.seq;
    }
    const plane = this.planeThrough(this.pos);
    const onPlane = this.view.rayAt(e.clientX, e.clientY).ray.intersectPlane(plane, new THREE.Vector3());
    const offset = onPlane ? this.pos.clone().sub(onPlane) : new THREE.Vector3();
    this.drag = { mode: hit ? 'grip' : 'touch', plane, offset, x: e.clientX, y: e.clientY };
    this.view.controls.enabled = false;
  }

  move(e) {
    const d = this.drag;
    if (!d) return;
    if (e.shiftKey) {
      if (this.frame?.grip?.position_only && !this.warned) {
        this.ui.notice('info', 'Turning holds the bone only in a whole-bone grip: press Shift before the button, or O');
        this.warned = true;
      }
      const { up, right } = this.cameraAxes();
      this.turn(up, (e.clientX - d.x) * TURN_PER_PIXEL);
      this.turn(right, (e.clientY - d.y) * TURN_PER_PIXEL);
      const onPlane = this.view.rayAt(e.clientX, e.clientY).ray.intersectPlane(d.plane, new THREE.Vector3());
      if (onPlane) d.offset = this.pos.clone().sub(onPlane); // turning does not move the grip
    } else {
      const onPlane = this.view.rayAt(e.clientX, e.clientY).ray.intersectPlane(d.plane, new THREE.Vector3());
      if (onPlane) { this.pos.copy(onPlane.add(d.offset)); this.dirty = true; }
    }
    d.x = e.clientX; d.y = e.clientY;
  }

  up(e) {
    if (e.button !== 0 || !this.drag) return;
    if (this.drag.mode === 'grip') this.command({ type: 'release' });
    this.drag = null;
    this.view.controls.enabled = true;
  }

  wheel(e) {
    if (!(this.drag || this.held || (this.frame && this.frame.touch))) return;
    e.preventDefault();
    e.stopPropagation();
    this.moveBy(this.cameraAxes().forward.multiplyScalar(-Math.sign(e.deltaY) * DEPTH_STEP));
  }

  key(e) {
    if (this.ui.stopped) return;
    if (e.target instanceof HTMLInputElement || e.target instanceof HTMLTextAreaElement || e.target.isContentEditable) {
      if (e.target.id !== 'label') return;
      if (e.key === 'Enter') { this.takeKey(); e.target.blur(); e.preventDefault(); }
      if (e.key === 'Escape') e.target.blur();
      return;
    }
    const k = e.key.length === 1 ? e.key.toLowerCase() : e.key;
    if (e.altKey || e.metaKey || (e.ctrlKey && k !== 'z')) return; // the browser's own shortcuts
    if (e.repeat && !REPEATS.has(k)) return; // a held K takes one key, a held Space one pause
    const step = e.shiftKey ? 0.05 : 0.01;
    const { forward, up, right } = this.cameraAxes();
    const actions = {
      k: () => this.takeKey(), Enter: () => this.takeKey(),
      u: () => this.command({ type: 'undo' }),
      x: () => this.command({ type: 'unpin' }),
      z: () => e.ctrlKey && this.command({ type: 'undo' }),
      '/': () => e.shiftKey && this.ui.toggleHelp(), // "?" on layouts that report the unshifted key
      ' ': () => this.ui.togglePause(), p: () => this.ui.togglePause(),
      g: () => this.toggleHold(), r: () => this.release(), Escape: () => { this.release(); this.ui.hideHelp(); },
      t: () => this.command({ type: 'touch', on: !(this.frame && this.frame.touch) }),
      o: () => this.command({ type: 'position_only', on: !(this.frame && this.frame.position_only) }),
      q: () => this.turn(forward, -5 * DEG), e: () => this.turn(forward, 5 * DEG),
      '?': () => this.ui.toggleHelp(), h: () => this.ui.toggleHelp(),
      ArrowLeft: () => this.held && this.moveBy(right.multiplyScalar(-step)),
      ArrowRight: () => this.held && this.moveBy(right.multiplyScalar(step)),
      ArrowUp: () => this.held && this.moveBy(up.multiplyScalar(step)),
      ArrowDown: () => this.held && this.moveBy(up.multiplyScalar(-step)),
      PageUp: () => this.held && this.moveBy(forward.multiplyScalar(step)),
      PageDown: () => this.held && this.moveBy(forward.multiplyScalar(-step)),
    };
    if (actions[k]) { actions[k](); e.preventDefault(); }
  }

  // Pin the clicked bone at the clicked point (Shift: its orientation too), or unpin it if
  // it is pinned.
  togglePin(hit, orient) {
    const pinned = (this.frame?.pins || []).some((p) => p.bone === hit.bone);
    if (pinned) this.command({ type: 'unpin', bone: hit.bone });
    else this.command({ type: 'pin', bone: hit.bone, point: hit.point.toArray(), orient });
  }

  takeKey() {
    const label = this.ui.takeLabel();
    this.command(label ? { type: 'key', label } : { type: 'key' });
  }

  toggleHold() {
    if ((this.frame && this.frame.grip) || this.held) { this.release(); return; }
    this.command({ type: 'grip' });
    this.held = true;
    this.holdSeq = this.link.seq;
  }

  // Let go (send: tell the server; not after the session stopped).
  release(send = true) {
    if (send && ((this.frame && this.frame.grip) || this.held || this.drag)) this.command({ type: 'release' });
    this.held = false;
    this.drag = null;
    this.view.controls.enabled = true;
  }

  // A 3D mouse (a gamepad with >= 6 axes): axes 0-2 move the target along the camera's right,
  // up and towards-the-viewer axes, 3-5 turn it about them; button 0 grips / lets go, 1 keys.
  poll(dt) {
    const pad = [...(navigator.getGamepads ? navigator.getGamepads() : [])].find((g) => g && g.axes.length >= 6);
    this.pad = pad ? pad.id : null;
    if (!pad || this.ui.stopped) return;
    const a = pad.axes.map((v) => (Math.abs(v) < PAD_DEAD ? 0 : v));
    const axes = () => {
      const { forward, up, right } = this.cameraAxes();
      return [right, up, forward.negate()].map((v, i) => v.multiplyScalar(PAD_SIGNS[i]));
    };
    const move = new THREE.Vector3();
    axes().forEach((v, i) => move.addScaledVector(v, a[i]));
    if (move.lengthSq() > 0) this.moveBy(move.multiplyScalar(PAD_SPEED * dt));
    axes().forEach((v, i) => a[3 + i] && this.turn(v, a[3 + i] * PAD_TURN * dt));
    const pressed = pad.buttons.map((b) => b.pressed);
    if (pressed[0] && !this.padWas?.[0]) this.toggleHold();
    if (pressed[1] && !this.padWas?.[1]) this.takeKey();
    this.padWas = pressed;
  }
}
