// Pure parts of the viewer: `npm test` (node --test tests/). The browser side is
// tested by tests/test_web_client.py.
import assert from 'node:assert/strict';
import test from 'node:test';
import { decodeFrame, frameSize, framesMissed, parseHello, streamUrl } from '../src/protocol.js';
import { chainRotation, foldMissing, quatMultiply, vrmBoneName } from '../src/retarget.js';
import { angleDeg, StreamStats } from '../src/stats.js';

const close = (a, b, eps = 1e-9) => assert.ok(Math.abs(a - b) < eps, `${a} != ${b}`);

test('frame index gaps count lost frames, wrap at 2^32, ignore restarts', () => {
  assert.equal(framesMissed(null, 5), 0);
  assert.equal(framesMissed(5, 6), 0);
  assert.equal(framesMissed(5, 9), 3);
  assert.equal(framesMissed(0xffffffff, 0), 0);
  assert.equal(framesMissed(0xfffffffe, 1), 2);
  assert.equal(framesMissed(500, 0), 0); // engine restarted
});

test('binary frames are checked', () => {
  assert.equal(frameSize(21), 380);
  assert.throws(() => decodeFrame(new ArrayBuffer(10)), /shorter than its header/);
  const buf = new ArrayBuffer(380);
  assert.throws(() => decodeFrame(buf), /not a version-1 pose frame/);
  const v = new DataView(buf);
  [76, 80, 70, 49].forEach((c, i) => v.setUint8(i, c)); // "LPF1"
  v.setUint16(4, 1, true);
  v.setUint16(6, 20, true);
  assert.throws(() => decodeFrame(buf), /does not match its 20 bones/);
  v.setUint16(6, 21, true);
  v.setUint32(8, 7, true);
  v.setFloat64(16, 0.25, true);
  const f = decodeFrame(buf);
  assert.equal(f.index, 7);
  assert.equal(f.audioTime, 0.25);
  assert.equal(f.rotations.length, 84);
});

test('hello is validated', () => {
  const hello = { type: 'hello', protocol: 'live-performer', version: 1, bones: ['Hips', 'Spine'], parents: [-1, 0],
    rest_offsets: [[0, 1, 0], [0, 0.1, 0]] };
  assert.deepEqual(parseHello(hello).jointNames, ['Hips', 'Spine']);
  assert.throws(() => parseHello({ ...hello, version: 2 }), /unsupported protocol/);
  assert.throws(() => parseHello({ ...hello, parents: [-1, 1] }), /parents must come first/);
  assert.throws(() => parseHello({ ...hello, rest_offsets: [] }), /same length/);
});

test('stream address: same host, ?ws= override, token and format passed on', () => {
  const loc = (href) => new URL(href);
  assert.equal(streamUrl(loc('http://10.0.0.5:8765/')), 'ws://10.0.0.5:8765/ws');
  assert.equal(streamUrl(loc('https://stage.example/viewer/')), 'wss://stage.example/ws');
  assert.equal(streamUrl(loc('file:///x/index.html')), 'ws://127.0.0.1:8765/ws');
  assert.equal(streamUrl(loc('http://a:1/?ws=ws://b:2/ws&token=s&format=json')), 'ws://b:2/ws?token=s&format=json');
});

test('missing avatar bones fold into their children; missing leaves are dropped', () => {
  // Hips, Spine, Chest(missing), Neck, LeftShoulder(missing), LeftUpperArm, Toes(missing leaf)
  const parents = [-1, 0, 1, 2, 2, 4, 0];
  const present = [true, true, false, true, false, true, false];
  assert.deepEqual(foldMissing(parents, present), [
    { bone: 0, chain: [0] }, { bone: 1, chain: [1] }, { bone: 3, chain: [2, 3] }, { bone: 5, chain: [2, 4, 5] },
  ]);
  assert.equal(vrmBoneName('LeftUpperArm'), 'leftUpperArm');
});

test('quaternion product matches the rotation composition', () => {
  const s = Math.SQRT1_2;
  const z90 = [0, 0, s, s], x90 = [s, 0, 0, s];
  const out = quatMultiply(z90, 0, x90, 0, new Float64Array(4)); // rotate about x, then about z
  // z90 * x90 maps +Y -> +Z (x90) -> +Z (z90); expected quaternion (0.5, 0.5, 0.5, 0.5)
  [0.5, 0.5, 0.5, 0.5].forEach((v, i) => close(out[i], v, 1e-12));
  const rot = Float32Array.from([...z90, ...x90]);
  const chained = chainRotation(rot, [0, 1]);
  [0.5, 0.5, 0.5, 0.5].forEach((v, i) => close(chained[i], v, 1e-7));
  close(angleDeg(z90, [0, 0, 0, 1], 0), 90, 1e-6);
});

test('stats: fps over a 1 s window, delay, drops and joint speed', () => {
  const stats = new StreamStats(1);
  const rot = (deg) => Float32Array.from([0, 0, Math.sin((deg * Math.PI) / 360), Math.cos((deg * Math.PI) / 360)]);
  for (let i = 0; i < 60; i++) {
    if (i === 40) continue; // one frame lost
    const t = 1000 + i / 30;
    stats.onFrame({ index: i, audioTime: i / 30, sendTime: t - 0.02, rotations: rot(3 * i) }, t * 1000);
  }
  assert.equal(stats.framesReceived, 59);
  assert.equal(stats.dropped, 1);
  assert.ok(stats.fps >= 28 && stats.fps <= 30, `${stats.fps}`); // about 30 frames, one lost, in the last second
  close(stats.delayMs, 20, 1e-3);
  close(stats.speeds[0], 90, 1); // 3 degrees per frame at 30 fps
  stats.tick(1000 * 1000 + 5000);
  assert.equal(stats.fps, 0);
});

test('state messages carry the stage; bad ones are refused with the reason', async () => {
  const { parseState } = await import('../src/stage.js');
  assert.deepEqual(parseState({ type: 'state', stage: [3, 2], facing: 'audience' }),
    { width: 3, depth: 2, facing: 'audience', spot: null, spots: [] });
  assert.deepEqual(parseState({ type: 'state', stage: [0, 0] }), { width: 0, depth: 0, facing: 'free', spot: null, spots: [] });
  // an ensemble performer's: its own spot and every performer's
  const two = parseState({ type: 'state', stage: [3, 2], facing: 'free', spot: [0.9, 0, 1.2, 2],
                           spots: [[-0.9, 0, 1.2, 2], [0.9, 0, 1.2, 2]] });
  assert.deepEqual(two.spot, { x: 0.9, z: 0, width: 1.2, depth: 2 });
  assert.deepEqual(two.spots.map((r) => r.x), [-0.9, 0.9]);
  assert.throws(() => parseState({ type: 'state', stage: [3, 2], spot: [0, 0, 1] }), /spot must be/);
  assert.throws(() => parseState({ type: 'state', stage: [3, 2], spots: [[0, 0, -1, 1]] }), /spots\[0\] must be/);
  assert.throws(() => parseState({ type: 'hello' }), /expected a state message/);
  assert.throws(() => parseState({ type: 'state', stage: [3] }), /stage must be/);
  assert.throws(() => parseState({ type: 'state', stage: [-1, 2] }), /stage must be/);
});

test('the follow camera drifts after the performer and stays near its stage', async () => {
  const { fitDistance, followStep } = await import('../src/stage.js');
  const [dx, dz] = followStep([0, 0], 1, -2, 0.1);
  close(dx, 0.1);
  close(dz, -0.2);
  // a performer 10 m out on a 3x2 stage pulls the target no further than the stage plus 0.5 m
  const [ex, ez] = followStep([0, 0], 10, 10, 1.0, { width: 3, depth: 2 });
  close(ex, 2.0);
  close(ez, 1.5);
  // in an ensemble: no further than its own spot plus 0.5 m (the spot at x = 0.9, 1.2 x 2 m)
  const [sx, sz] = followStep([0, 0], -10, 0, 1.0, { x: 0.9, z: 0, width: 1.2, depth: 2 });
  close(sx, 0.9 - 0.6 - 0.5);
  close(sz, 0);
  const { corners } = await import('../src/stage.js');
  assert.deepEqual(corners({ x: 1, z: -1, width: 2, depth: 4 }), [[0, -3], [2, -3], [2, 1], [0, 1]]);
  assert.ok(fitDistance(6, 5) > fitDistance(1, 1));
  assert.ok(fitDistance(1, 1) >= 3.0);
});
