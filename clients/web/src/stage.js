// The stage the performer dances on (docs/stage.md): its rectangle on the floor and a camera
// that keeps the performer in view while it travels.
//
// The server sends {"type": "state", "stage": [W, D], "facing": "free"|"audience"} after the
// hello and whenever the stage changes (W x D metres centred on the origin; [0, 0]: in place).
// parseState and followStep are pure (node --test); StageOutline draws with three.js.

/** Check a state message (JSON-parsed); returns {width, depth, facing}; throws Error naming what is wrong. */
export function parseState(msg) {
  if (!msg || msg.type !== 'state') throw new Error(`expected a state message, got ${JSON.stringify(msg?.type)}`);
  const stage = msg.stage;
  if (!Array.isArray(stage) || stage.length !== 2 || !stage.every((v) => Number.isFinite(v) && v >= 0)) {
    throw new Error(`state: stage must be [width, depth] in metres (0 or more), got ${JSON.stringify(stage)}`);
  }
  return { width: stage[0], depth: stage[1], facing: typeof msg.facing === 'string' ? msg.facing : 'free' };
}

/**
 * One frame of the follow camera: the orbit target moves a share `rate` (0..1) of the way to
 * the performer's floor position (x, z), and no further than `margin` metres from the stage's
 * centre plus half its size (so a performer at the stage's edge stays in the middle of the
 * picture, and the picture never wanders off a stage it has). Returns the [dx, dz] the target
 * (and the camera with it) moves.
 */
export function followStep(target, x, z, rate = 0.08, stage = null, margin = 0.5) {
  let gx = x, gz = z;
  if (stage && stage.width > 0 && stage.depth > 0) {
    const hx = stage.width / 2 + margin, hz = stage.depth / 2 + margin;
    gx = Math.max(-hx, Math.min(hx, gx));
    gz = Math.max(-hz, Math.min(hz, gz));
  }
  return [rate * (gx - target[0]), rate * (gz - target[1])];
}

/** Distance (m) at which a camera with vertical field of view `fovDeg` and aspect `aspect`
 * sees a stage of `width` x `depth` metres and a 1.9-m performer on it, with a little room. */
export function fitDistance(width, depth, fovDeg = 40, aspect = 16 / 9) {
  const half = (fovDeg * Math.PI) / 360;
  const byHeight = (Math.max(1.9, depth * 0.6) * 0.5 + 0.3) / Math.tan(half);
  const byWidth = (width * 0.5 + 0.5) / (Math.tan(half) * Math.max(aspect, 0.3));
  return Math.max(3.0, byHeight, byWidth + depth / 2);
}

/** The stage's rectangle on the floor (three.js), hidden for an in-place stage. */
export class StageOutline {
  constructor(THREE, scene) {
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute('position', new THREE.BufferAttribute(new Float32Array(12), 3));
    this.line = new THREE.LineLoop(geometry, new THREE.LineBasicMaterial({ color: 0xffd166 }));
    this.line.name = 'StageOutline';
    this.line.visible = false;
    this.line.frustumCulled = false;
    scene.add(this.line);
    this.stage = null;
  }

  /** Show `stage` ({width, depth}) as its rectangle 5 mm above the floor. */
  set(stage) {
    this.stage = stage;
    const on = stage.width > 0 && stage.depth > 0;
    this.line.visible = on;
    if (!on) return;
    const w = stage.width / 2, d = stage.depth / 2, y = 0.005;
    const p = this.line.geometry.attributes.position;
    p.array.set([-w, y, -d, w, y, -d, w, y, d, -w, y, d]);
    p.needsUpdate = true;
  }
}
