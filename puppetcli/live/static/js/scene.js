// The 3D view: the rig's shapes placed by the streamed body poses, joints, ground, props,
// the pointer, the coupling line and the felt-force arrow.
import * as THREE from 'three';
import { OrbitControls } from '/static/vendor/three/OrbitControls.js';

const PIN_COLOR = 0x2f7fd8;
const v3 = (a) => new THREE.Vector3(a[0], a[1], a[2]);
const q4 = (q) => new THREE.Quaternion(q[1], q[2], q[3], q[0]); // (w,x,y,z) -> three's (x,y,z,w)

function geometryOf(shape) {
  if (shape.kind === 'sphere') return new THREE.SphereGeometry(shape.radius, 24, 16);
  if (shape.kind === 'capsule') return new THREE.CapsuleGeometry(shape.radius, 2 * shape.half[1], 8, 20);
  return new THREE.BoxGeometry(2 * shape.half[0], 2 * shape.half[1], 2 * shape.half[2]);
}

// A soft round "contact shadow": a radial gradient on a disc just above the ground, under the
// root body (no shadow maps).
function softShadow() {
  const c = document.createElement('canvas');
  c.width = c.height = 64;
  const g = c.getContext('2d');
  const grad = g.createRadialGradient(32, 32, 0, 32, 32, 32);
  grad.addColorStop(0, 'rgba(0,0,0,0.22)');
  grad.addColorStop(1, 'rgba(0,0,0,0)');
  g.fillStyle = grad;
  g.fillRect(0, 0, 64, 64);
  const disc = new THREE.Mesh(new THREE.PlaneGeometry(0.7, 0.7),
    new THREE.MeshBasicMaterial({ map: new THREE.CanvasTexture(c), transparent: true, depthWrite: false }));
  disc.rotation.x = -Math.PI / 2;
  return disc;
}

export class View {
  constructor(container, hello) {
    this.hello = hello;
    // Antialiasing only where the pixels are small (a high-density display): it costs a
    // software renderer (no GPU) more than half its frame rate.
    this.renderer = new THREE.WebGLRenderer({ antialias: window.devicePixelRatio > 1 });
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio, 2));
    this.renderer.setSize(container.clientWidth, container.clientHeight);
    container.appendChild(this.renderer.domElement);
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(hello.colors.background);
    this.camera = new THREE.PerspectiveCamera(40, container.clientWidth / container.clientHeight, 0.01, 200);
    this.controls = new OrbitControls(this.camera, this.renderer.domElement);
    this.placeCamera(hello.camera);
    this.addLights();
    this.pickable = [];
    this.bodies = [];
    this.addShapes(hello);
    this.addGround(hello);
    this.addPointer(hello);
    window.addEventListener('resize', () => this.resize(container));
  }

  placeCamera(cam) {
    const target = v3(cam.target);
    const az = THREE.MathUtils.degToRad(35), el = THREE.MathUtils.degToRad(18);
    const dir = new THREE.Vector3(Math.sin(az) * Math.cos(el), Math.sin(el), Math.cos(az) * Math.cos(el));
    this.camera.position.copy(target).addScaledVector(dir, 0.75 * cam.distance);
    this.controls.target.copy(target);
    this.controls.update();
  }

  addLights() {
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x8a8f96, 2.2));
    const sun = new THREE.DirectionalLight(0xffffff, 1.6);
    sun.position.set(-2, 5, 3);
    this.scene.add(sun);
  }

  addShapes(hello) {
    const colors = hello.colors;
    for (let b = 0; b < hello.bodies; b++) {
      const group = new THREE.Group();
      this.bodies.push(group);
      this.scene.add(group);
    }
    const material = {
      bone: new THREE.MeshLambertMaterial({ color: colors.bone }),
      prop: new THREE.MeshLambertMaterial({ color: colors.prop }),
    };
    this.boneShape = {};
    const boneOfBody = new Map(hello.bones.map((b) => [b.body, b.name]));
    for (const shape of hello.shapes) {
      const mesh = new THREE.Mesh(geometryOf(shape), material[shape.role] || material.prop);
      mesh.position.copy(v3(shape.pos));
      mesh.quaternion.copy(q4(shape.quat));
      const bone = shape.role === 'bone' ? shape.bone || boneOfBody.get(shape.body) : null;
      if (bone) {
        mesh.userData.bone = bone;
        this.pickable.push(mesh);
        if (!(bone in this.boneShape)) this.boneShape[bone] = mesh;
      }
      (shape.body >= 0 ? this.bodies[shape.body] : this.scene).add(mesh);
    }
    const dot = new THREE.SphereGeometry(0.012, 12, 8);
    const dotMaterial = new THREE.MeshBasicMaterial({ color: colors.joint, depthTest: false });
    for (const joint of hello.joints) {
      const mesh = new THREE.Mesh(dot, dotMaterial);
      mesh.position.copy(v3(joint.pos));
      mesh.renderOrder = 10;
      this.bodies[joint.body].add(mesh);
    }
  }

  addGround(hello) {
    if (!hello.ground) return;
    const y = hello.ground.height;
    const plane = new THREE.Mesh(new THREE.PlaneGeometry(8, 8),
      new THREE.MeshLambertMaterial({ color: hello.colors.ground }));
    plane.rotation.x = -Math.PI / 2;
    plane.position.set(hello.camera.target[0], y, hello.camera.target[2]);
    this.scene.add(plane);
    const grid = new THREE.GridHelper(8, 32, hello.colors.grid, hello.colors.grid);
    grid.position.set(hello.camera.target[0], y + 0.001, hello.camera.target[2]);
    this.scene.add(grid);
    this.shadow = softShadow();
    this.shadow.position.y = y + 0.002;
    this.scene.add(this.shadow);
  }

  addPointer(hello) {
    const color = new THREE.Color(hello.colors.pointer);
    const radius = Math.max(hello.pointer_radius, 0.015);
    this.pointer = new THREE.Mesh(new THREE.SphereGeometry(radius, 20, 14),
      new THREE.MeshLambertMaterial({ color, transparent: true, opacity: 0.6 }));
    this.pointer.add(new THREE.AxesHelper(0.05));
    this.scene.add(this.pointer);
    this.ghost = new THREE.Mesh(new THREE.SphereGeometry(radius, 16, 10),
      new THREE.MeshBasicMaterial({ color, transparent: true, opacity: 0.2, depthWrite: false }));
    this.scene.add(this.ghost);
    const line = new THREE.BufferGeometry().setFromPoints([new THREE.Vector3(), new THREE.Vector3()]);
    this.coupling = new THREE.Line(line, new THREE.LineBasicMaterial({ color: hello.colors.coupling }));
    this.coupling.frustumCulled = false;
    this.scene.add(this.coupling);
    this.arrow = new THREE.ArrowHelper(new THREE.Vector3(0, 1, 0), new THREE.Vector3(), 0.1, 0xc0392b);
    this.scene.add(this.arrow);
    this.pins = new THREE.Group(); // one marker per pin, made as pins come
    this.scene.add(this.pins);
    this.pinGeometry = { point: new THREE.SphereGeometry(0.014, 12, 8), bone: new THREE.BoxGeometry(0.04, 0.04, 0.04) };
    this.pinMaterial = {
      point: new THREE.MeshBasicMaterial({ color: PIN_COLOR, depthTest: false }),
      bone: new THREE.MeshBasicMaterial({ color: PIN_COLOR, depthTest: false, wireframe: true }),
    };
  }

  // The pins: a ball where a point pin holds its point, a wire cube for a whole-bone pin.
  updatePins(pins) {
    const signature = pins.map((p) => `${p.bone}:${p.orient}`).join();
    if (signature !== this.pinSignature) { // pinned or unpinned: new markers
      this.pinSignature = signature;
      this.pins.clear();
      for (const pin of pins) {
        const kind = pin.orient ? 'bone' : 'point';
        const mark = new THREE.Mesh(this.pinGeometry[kind], this.pinMaterial[kind]);
        mark.renderOrder = 11;
        mark.userData.bone = pin.bone;
        this.pins.add(mark);
      }
    }
    pins.forEach((pin, i) => this.pins.children[i].position.copy(v3(pin.target)));
  }

  update(frame) {
    const p = frame.body_pos, q = frame.body_quat;
    for (let i = 0; i < this.bodies.length; i++) {
      this.bodies[i].position.set(p[3 * i], p[3 * i + 1], p[3 * i + 2]);
      this.bodies[i].quaternion.set(q[4 * i + 1], q[4 * i + 2], q[4 * i + 3], q[4 * i]);
    }
    if (this.shadow && this.bodies.length) this.shadow.position.set(p[0], this.shadow.position.y, p[2]);
    this.pointer.position.copy(v3(frame.pointer.pos));
    this.pointer.quaternion.copy(q4(frame.pointer.quat));
    this.pointer.material.opacity = frame.touch ? 1.0 : 0.6;
    const target = v3(frame.target.pos);
    this.ghost.position.copy(target);
    this.ghost.visible = target.distanceTo(this.pointer.position) > 0.01;
    this.coupling.visible = !!frame.grip;
    if (frame.grip) {
      const pos = this.coupling.geometry.attributes.position;
      pos.setXYZ(0, ...frame.pointer.pos);
      pos.setXYZ(1, ...frame.grip.point);
      pos.needsUpdate = true;
    }
    this.updatePins(frame.pins || []);
    const force = v3(frame.wrench.force);
    const size = force.length();
    this.arrow.visible = size > 0.2;
    if (this.arrow.visible) {
      this.arrow.position.copy(this.pointer.position);
      this.arrow.setDirection(force.clone().normalize());
      this.arrow.setLength(Math.min(0.5, 0.01 * size), 0.03, 0.02);
    }
  }

  render() { this.renderer.render(this.scene, this.camera); }

  // Dynamic resolution: a page drawing slower than ~40 frames/s (a software renderer, a
  // weak GPU) draws fewer pixels, down to half the density; a fast one goes back up.
  adapt(frameMs) {
    this.frameMs = this.frameMs === undefined ? frameMs : 0.9 * this.frameMs + 0.1 * frameMs;
    const now = performance.now();
    if (now - (this.adapted || 0) < 1000) return;
    const ratio = this.renderer.getPixelRatio(), best = Math.min(window.devicePixelRatio, 2);
    let next = ratio;
    if (this.frameMs > 25 && ratio > 0.5) next = Math.max(0.5, ratio * 0.8);
    else if (this.frameMs < 18 && ratio < best) next = Math.min(best, ratio * 1.25);
    if (next !== ratio) {
      this.renderer.setPixelRatio(next);
      this.renderer.setSize(this.renderer.domElement.clientWidth, this.renderer.domElement.clientHeight);
      this.adapted = now;
    }
  }

  // Whether the camera moved since the last call (the page then redraws without a new frame).
  moved() {
    const now = this.camera.matrixWorld.elements.join();
    const changed = now !== this.lastCamera;
    this.lastCamera = now;
    return changed;
  }

  resize(container) {
    this.camera.aspect = container.clientWidth / container.clientHeight;
    this.camera.updateProjectionMatrix();
    this.renderer.setSize(container.clientWidth, container.clientHeight);
  }

  // The bone under a page position (clientX/Y), with the world point hit, or null.
  pick(x, y) {
    const ray = this.rayAt(x, y);
    const hit = ray.intersectObjects(this.pickable, false)[0];
    return hit ? { bone: hit.object.userData.bone, point: hit.point } : null;
  }

  rayAt(x, y) {
    const rect = this.renderer.domElement.getBoundingClientRect();
    const ndc = new THREE.Vector2(((x - rect.left) / rect.width) * 2 - 1, -((y - rect.top) / rect.height) * 2 + 1);
    const ray = new THREE.Raycaster();
    ray.setFromCamera(ndc, this.camera);
    return ray;
  }

  screenOfWorld(point) {
    const rect = this.renderer.domElement.getBoundingClientRect();
    const v = v3(point).project(this.camera);
    return { x: rect.left + ((v.x + 1) / 2) * rect.width, y: rect.top + ((1 - v.y) / 2) * rect.height };
  }

  screenOf(bone) {
    const mesh = this.boneShape[bone];
    if (!mesh) return null;
    const centre = new THREE.Vector3();
    mesh.getWorldPosition(centre);
    return this.screenOfWorld([centre.x, centre.y, centre.z]);
  }

  // A small picture of what is on screen now (call right after render()).
  thumbnail() {
    const c = document.createElement('canvas');
    c.width = 160; c.height = 120;
    const src = this.renderer.domElement;
    const s = Math.min(src.width / 4, src.height / 3);
    c.getContext('2d').drawImage(src, (src.width - 4 * s) / 2, (src.height - 3 * s) / 2, 4 * s, 3 * s, 0, 0, 160, 120);
    return c.toDataURL('image/jpeg', 0.75);
  }
}
