// The stage the performer dances on (docs/stage.md): its rectangle on the floor and a camera
// that keeps the performer in view while it travels.
//
// The server sends {"type": "state", "stage": [W, D], "facing": "free"|"audience"} after the
// hello and whenever the stage changes (W x D metres centred on the origin; [0, 0]: in place).
// A performer of an ensemble adds "spot": [x, z, w, d], the part of the stage it is kept inside
// (centre x, z and size, metres), and "spots": every performer's, its own among them.
// parseState and followStep are pure (node --test); StageOutline draws with three.js.

/** [x, z, w, d] (metres, sizes 0 or more) -> {x, z, width, depth}; throws Error naming `what`. */
function parseSpot(v, what) {
  if (!Array.isArray(v) || v.length !== 4 || !v.every(Number.isFinite) || v[2] < 0 || v[3] < 0) {
    throw new Error(`state: ${what} must be [centre x, centre z, width, depth] in metres, got ${JSON.stringify(v)}`);
  }
  return { x: v[0], z: v[1], width: v[2], depth: v[3] };
}

/** Check a state message (JSON-parsed); returns {width, depth, facing, spot, spots} (spot: this
 * performer's {x, z, width, depth} or null, spots: every performer's, [] without an ensemble);
 * throws Error naming what is wrong. */
export function parseState(msg) {
  if (!msg || msg.type !== 'state') throw new Error(`expected a state message, got ${JSON.stringify(msg?.type)}`);
  const stage = msg.stage;
  if (!Array.isArray(stage) || stage.length !== 2 || !stage.every((v) => Number.isFinite(v) && v >= 0)) {
    throw new Error(`state: stage must be [width, depth] in metres (0 or more), got ${JSON.stringify(stage)}`);
  }
  const spot = msg.spot == null ? null : parseSpot(msg.spot, 'spot');
  if (msg.spots != null && !Array.isArray(msg.spots)) throw new Error(`state: spots must be a list, got ${JSON.stringify(msg.spots)}`);
  const spots = (msg.spots ?? (spot ? [msg.spot] : [])).map((v, i) => parseSpot(v, `spots[${i}]`));
  return { width: stage[0], depth: stage[1], facing: typeof msg.facing === 'string' ? msg.facing : 'free', spot, spots };
}

/**
 * One frame of the follow camera: the orbit target moves a share `rate` (0..1) of the way to
 * the performer's floor position (x, z), and no further than `margin` metres outside `stage`
 * ({width, depth} centred on the origin, or {x, z, width, depth}: an ensemble performer's spot),
 * so a performer at an edge stays in the middle of the picture and the picture never wanders
 * off the floor it dances on. Returns the [dx, dz] the target (and the camera with it) moves.
 */
export function followStep(target, x, z, rate = 0.08, stage = null, margin = 0.5) {
  let gx = x, gz = z;
  if (stage && stage.width > 0 && stage.depth > 0) {
    const cx = stage.x ?? 0, cz = stage.z ?? 0;
    const hx = stage.width / 2 + margin, hz = stage.depth / 2 + margin;
    gx = Math.max(cx - hx, Math.min(cx + hx, gx));
    gz = Math.max(cz - hz, Math.min(cz + hz, gz));
  }
  return [rate * (gx - target[0]), rate * (gz - target[1])];
}

/** The four floor corners [[x, z], ...] of a rectangle {x?, z?, width, depth} (metres). */
export function corners(r) {
  const cx = r.x ?? 0, cz = r.z ?? 0, w = r.width / 2, d = r.depth / 2;
  return [[cx - w, cz - d], [cx + w, cz - d], [cx + w, cz + d], [cx - w, cz + d]];
}

/** Distance (m) at which a camera with vertical field of view `fovDeg` and aspect `aspect`
 * sees a stage of `width` x `depth` metres and a 1.9-m performer on it, with a little room. */
export function fitDistance(width, depth, fovDeg = 40, aspect = 16 / 9) {
  const half = (fovDeg * Math.PI) / 360;
  const byHeight = (Math.max(1.9, depth * 0.6) * 0.5 + 0.3) / Math.tan(half);
  const byWidth = (width * 0.5 + 0.5) / (Math.tan(half) * Math.max(aspect, 0.3));
  return Math.max(3.0, byHeight, byWidth + depth / 2);
}

/** Colours on the floor: the stage, this performer's spot, the other performers' spots. */
export const STAGE_COLOR = 0xffd166, SPOT_COLOR = 0x4cc9f0, OTHER_SPOT_COLOR = 0xb388eb;

/** The stage's rectangle on the floor (three.js), hidden for an in-place stage; in an ensemble
 * also every performer's spot, this performer's brighter (and 2 mm higher, over the others). */
export class StageOutline {
  constructor(THREE, scene) {
    this.THREE = THREE;
    this.scene = scene;
    this.line = this._loop(STAGE_COLOR, 'StageOutline');
    this.spot = this._loop(SPOT_COLOR, 'SpotOutline'); // this performer's
    this.others = []; // the other performers' spots, one loop each
    this.stage = null;
  }

  _loop(color, name) {
    const geometry = new this.THREE.BufferGeometry();
    geometry.setAttribute('position', new this.THREE.BufferAttribute(new Float32Array(12), 3));
    const line = new this.THREE.LineLoop(geometry, new this.THREE.LineBasicMaterial({ color }));
    line.name = name;
    line.visible = false;
    line.frustumCulled = false;
    this.scene.add(line);
    return line;
  }

  static _place(line, rect, y) {
    const on = rect !== null && rect.width > 0 && rect.depth > 0;
    line.visible = on;
    if (!on) return;
    line.geometry.attributes.position.array.set(corners(rect).flatMap(([x, z]) => [x, y, z]));
    line.geometry.attributes.position.needsUpdate = true;
  }

  /** Show `stage` (parseState's {width, depth, spot, spots}) as rectangles a few mm above the floor. */
  set(stage) {
    this.stage = stage;
    StageOutline._place(this.line, stage, 0.005);
    const own = stage.spot ?? null;
    StageOutline._place(this.spot, own, 0.007);
    const others = (stage.spots ?? []).filter((s) => !own || s.x !== own.x || s.z !== own.z);
    while (this.others.length < others.length) this.others.push(this._loop(OTHER_SPOT_COLOR, 'OtherSpotOutline'));
    this.others.forEach((line, i) => StageOutline._place(line, i < others.length ? others[i] : null, 0.005));
  }

  /** What is drawn: {stage, spot, others} as corner lists [[x, z], ...] (null / [] where nothing is). */
  drawn() {
    const read = (line) => {
      if (!line.visible) return null;
      const a = line.geometry.attributes.position.array;
      return [0, 1, 2, 3].map((k) => [a[3 * k], a[3 * k + 2]]);
    };
    return { stage: read(this.line), spot: read(this.spot), others: this.others.map(read).filter((c) => c) };
  }
}
