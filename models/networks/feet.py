"""Feet on the floor (issue 39, item 3): a planted foot stays put in the world, by two-bone leg IK.

The stream's last step on every frame (:meth:`FeetLock.step`, called by
:meth:`models.networks.dance_stream.DanceStream.push` just before a pose goes out). It
works in the world frame the final pose defines (its root position ``pose[0:3]`` and the
Hips rotation, travel and heading included), so it is the same whether the performer
dances in place or travels.

**Where a foot is in contact** is read from the memory, not guessed from the output:
every exemplar frame of the model's memory carries, per foot, whether the dancer's foot
was on the floor there (:func:`member_contacts`: its lowest point, heel or toe, at most
:data:`CONTACT_HEIGHT` above the lowest of its window, and its heel-toe midpoint moving at
most :data:`CONTACT_SPEED` horizontally), computed once per model and kept on it
(``dance_stream._cached_contacts``). The stream plays these flags along with the poses (the same
frame of the same exemplar, at the player's rate and warp) and hands this step the
value at the frame it plays (between 0 and 1: two frames interpolated; the idle counts as
standing). With them comes each exemplar window's lift, what puts its lowest foot point on
the floor: the body is raised or lowered by it (:data:`GROUND_RATE`), since the memory's
dancers stand at different heights on the default skeleton.

**The state** (:class:`FeetLock`, per foot, left first; ``reset()`` clears it):

- ``planted`` (2,) 1 while the foot is planted: the memory's contact value is over 0.5;
- ``plant`` (2, 3) the planted heel-toe midpoint in the world (x and z are held; the
  height follows the dance, so a heel or toe lift still shows);
- ``weight`` (2,) the IK blend weight: 1 while planted; from the frame the exemplar lifts
  the foot it falls to 0 over :data:`RELEASE_FRAMES` (smoothstep), so the foot is handed
  back to the dance without a jump. A foot planted anew starts where it is shown and its
  hold grows over :data:`PLANT_FRAMES`, so planting never jumps either;
- ``ground`` (2,) the body's height offset (the lift, low-passed twice).

**Every frame, per leg** (one compiled call, :func:`feet_kernel`; 0.014 ms a frame for both,
p99 0.042 ms: benchmarks/hop_profile.py): the body is grounded; the dance's heel-toe midpoint
is moved by ``weight`` towards the plant horizontally; a plant more than :data:`LEASH` from
the dance's foot is pulled after it, softly (:data:`LEASH_PULL`: the foot slides rather
than the leg being torn, where the exemplar's dancer travelled but the performer does not,
or the stage bends its path); the ankle
target follows from the foot's own orientation, which is kept; a target that would put
the heel or toe under the floor (:data:`FLOOR_PERCENTILE` of the memory's lowest foot
points) is raised onto it. Two-bone IK then bends the knee about the thigh's own hinge
axis (its local X, as the rig bends knees) to the hip-target distance, always forwards
and at least :data:`KNEE_MIN_DEG` (never past straight: a dance's hyper-extended knee is
bent the other way, its ankle where it was), at most :data:`KNEE_MAX_DEG` (a target nearer
the hip than that reaches is left short), swings the thigh onto the target, and turns
the foot back to its world orientation. A leg with nothing to do (no weight, above the
floor, knee bent forwards) is left bit for bit as it was.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from models.rig.humanoid import BONE_INDEX
from models.rig.skeleton import END_SITES, POINT_INDEX, load_default_skeleton

#: The knee's new flexion is read in [-90, 270) degrees, then capped at :data:`KNEE_MAX_DEG`.
#: Read in [-180, 180) (False, as before), a fold just past 180 wrapped round to "past straight"
#: and the leg snapped straight for a frame: a released foot the dance kicks away fast while the
#: hold keeps it over its plant folds the knee (DANCE_W_28 at 50 s, seed 3 on 3x2: 42 -> 168
#: degrees, then the toe 71 cm away and back in two frames). Switch for measuring.
KNEE_WRAP_FORWARD: bool = True

#: The most the IK bends a knee (degrees): a little past the dancers' own most (129 on the
#: validation dances), short of a leg folded flat.
KNEE_MAX_DEG: float = 150.0

#: Exemplar frames whose foot's lowest point (heel or toe) is at most this high above the
#: memory's floor (m) are contacts (the issue's metric counts 5 cm).
CONTACT_HEIGHT: float = 0.05
#: ... and whose heel-toe midpoint moves at most this fast horizontally (m a frame; 0.05 = 1.5
#: m/s: the memory is in place, so a dancer's travelling stance foot slides backwards under
#: the body in it and still counts).
CONTACT_SPEED: float = 0.05
#: Percentile of the memory's lowest foot points (both feet, every exemplar frame) that is the floor.
FLOOR_PERCENTILE: float = 2.0
#: Frames over which a released foot is handed back to the dance (smoothstep). A plant can lie up
#: to :data:`LEASH` from the dance's foot, so the hand-back is a swing of up to 0.4 m: over 10
#: frames the feet's horizontal acceleration reached 43-47 m/s^2 at its 99th percentile on the
#: bundled clip (3x2), 24-30 over 20, and on the validation songs (6x5) the jitter in the
#: dancers' canonical frame fell 0.944 -> 0.916 (in place 0.876), jerk 1.51 -> 1.38x, FSR
#: 0.18 -> 0.17, contact-foot speed 0.19 -> 0.13 m/s, band amplitude 0.947 -> 0.920
#: (benchmarks/studies/foot_skating.py --stage 6x5; 30 frames: 0.920, 1.36x, amplitude 0.916).
RELEASE_FRAMES: int = 20
#: Frames over which a foot newly planted comes to rest (its hold grows, smoothstep): no sudden stop.
PLANT_FRAMES: int = 3
#: How far a planted foot may lie from the dance's foot horizontally (m) before it is pulled after
#: it (a dancer travelling in the exemplar, or on the stage, leaves it behind) ...
LEASH: float = 0.4
#: ... by this share a frame of the way past it: the pull starts softly (at once, 1.0 with a 0.3 m
#: leash, the validation songs on a 6x5 stage: jitter 1.40, jerk 2.13 the dancers'; with 0.2 and
#: 0.4 m: 1.33, 1.88; benchmarks/studies/foot_skating.py --stage 6x5).
LEASH_PULL: float = 0.2
#: The least knee flexion the IK leaves (degrees): never past straight.
KNEE_MIN_DEG: float = 0.5
#: Soft reach (m): a target within this of the leg's full length, or beyond it, is approached
#: along an exponential and never quite met, so the knee straightens smoothly (near full reach
#: the knee angle a distance needs changes without bound: a centimetre snapped it by tens of
#: degrees). 0: the exact two-bone solution.
SOFT_REACH: float = 0.03
#: Grounding: the body's height is moved by the played exemplar's lift (what puts its window's
#: lowest foot point on the floor, :func:`member_contacts`) through two one-pole low-passes of
#: this rate a frame: the memory's dancers stand at different heights on the default skeleton,
#: and their exemplars take turns. 1: the lift as played, which the handover bends exactly as
#: it bends the root's height (:func:`bend_lift`), so the grounded height changes smoothly from
#: one dancer's to the next. 0: the height as the dance has it. (0.2 lagged the lift ~10
#: frames behind the root's bend: a handover from a dancer standing low (lift 0) to one
#: standing 0.45 m high (lift -0.45) took the hips to 0.49 m, and 13 of the hour soak's 120
#: stretches failed its vertical check; benchmarks/soak.py, docs/feet.md.)
GROUND_RATE: float = 1.0

_SIDES = ("Left", "Right")


def member_feet(positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lowest point height (..., 2) m, heel-toe midpoint (..., 2, 3)) of FK points (..., 30, 3), left first."""
    heel = positions[..., [POINT_INDEX["LeftHeel"], POINT_INDEX["RightHeel"]], :]
    toe = positions[..., [POINT_INDEX["LeftToes"], POINT_INDEX["RightToes"]], :]
    return np.minimum(heel[..., 1], toe[..., 1]), 0.5 * (heel + toe)


def member_contacts(positions: np.ndarray, counts: np.ndarray) -> tuple[np.ndarray, float]:
    """(contacts (K, M, F, 3) float32; the floor, m) of exemplar windows from their FK points
    ``positions`` (K, M, F, 30, 3) (``dance_stream.member_positions``), ``counts`` (K,) real
    ones (empty slots: 0). Channels 0 and 1: 1.0 where the left, right
    foot is on the floor (see the module docstring); channel 2: the window's lift, m, what
    puts its lowest foot point on the floor (the same for all its frames).

    Each window's own floor is its lowest foot point: the dancers' hip heights on the default
    skeleton put their feet at different heights (one dance's stays 9 cm up, another's at 0),
    so one height for the whole memory would find contacts in the low dancers only, and the
    stream, taking turns between them, would float and sink (:data:`GROUND_RATE`). The floor
    returned is the :data:`FLOOR_PERCENTILE` of all the memory's lowest foot points."""
    return feet_contacts(*member_feet(positions), counts)


def feet_contacts(low: np.ndarray, mid: np.ndarray, counts: np.ndarray) -> tuple[np.ndarray, float]:
    """:func:`member_contacts` from :func:`member_feet`'s (low (K, M, F, 2), mid (K, M, F, 2, 3)) of the
    windows' FK points, which ``dance_stream``'s start-up computes in chunks (member_tables.py)."""
    k, m, f = low.shape[:3]
    real = np.arange(m)[None, :] < np.asarray(counts)[:, None]
    if not real.any():
        return np.zeros((k, m, f, 3), np.float32), 0.0
    floor = float(np.percentile(low[real], FLOOR_PERCENTILE))
    own = low.min(axis=(2, 3), keepdims=True)  # (K, M, 1, 1): each window's floor
    speed = np.linalg.norm(np.gradient(mid[..., [0, 2]], axis=2), axis=-1)  # (K, M, F, 2) m a frame
    contact = (low <= own + CONTACT_HEIGHT) & (speed <= CONTACT_SPEED) & real[:, :, None, None]
    lift = np.where(real[:, :, None, None], floor - own, 0.0)
    return np.concatenate([contact, np.broadcast_to(lift, (k, m, f, 1))], axis=-1).astype(np.float32), floor


#: Bend the lift at a handover as the root's height is (:func:`bend_lift`; False: the new
#: exemplar's lift as it is, which GROUND_RATE < 1 then low-passes: the behaviour before).
BEND_LIFT: bool = True


def bend_lift(rows: np.ndarray, lift0: float, lift1: float, decay: np.ndarray) -> None:
    """The lift channel ``rows[:, 2]`` (F, 3; a new movement's contacts, :func:`member_contacts`)
    bent, in place, to continue from the last movement's lift ``lift0`` at the handover (and its
    change a frame ``lift1 - lift0``) with the Hermite weights ``decay`` (2, D) that bend the
    root's position there (``dance_jit.match_exemplar``): the root's height and its lift then
    change together, so the grounded height never dips between two dancers' heights."""
    if not BEND_LIFT:
        return
    n = min(decay.shape[1], len(rows))
    d0 = lift0 - float(rows[0, 2])
    d1 = (lift1 - lift0) - float(rows[1, 2] - rows[0, 2]) if len(rows) > 1 else 0.0
    rows[:n, 2] += decay[0, :n] * d0 + decay[1, :n] * d1


# -- the compiled step ---------------------------------------------------------------------------


@njit(cache=True, nogil=True, inline="always")
def _q(p, c):  # pragma: no cover - compiled
    return (float(p[c]), float(p[c + 1]), float(p[c + 2]), float(p[c + 3]))


@njit(cache=True, nogil=True, inline="always")
def _mul(a, b):  # pragma: no cover - compiled
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz)


@njit(cache=True, nogil=True, inline="always")
def _conj(q):  # pragma: no cover - compiled
    return (-q[0], -q[1], -q[2], q[3])


@njit(cache=True, nogil=True, inline="always")
def _unitq(q):  # pragma: no cover - compiled
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    n = max(n, 1e-12)
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


@njit(cache=True, nogil=True, inline="always")
def _rot(q, v):  # pragma: no cover - compiled
    """v rotated by unit quaternion q."""
    qx, qy, qz, qw = q
    vx, vy, vz = v
    tx, ty, tz = 2.0 * (qy * vz - qz * vy), 2.0 * (qz * vx - qx * vz), 2.0 * (qx * vy - qy * vx)
    return (vx + qw * tx + qy * tz - qz * ty, vy + qw * ty + qz * tx - qx * tz, vz + qw * tz + qx * ty - qy * tx)


@njit(cache=True, nogil=True, inline="always")
def _leg_fk(pose, f, bones, offs):  # pragma: no cover - compiled
    """Leg f of ``pose``: (hip joint, ankle, heel and toe from the ankle, Hips / thigh / shin / foot
    global rotations, shin local rotation)."""
    gh = _unitq(_q(pose, 3))
    gu = _mul(gh, _unitq(_q(pose, 3 + 4 * bones[f, 0])))
    ql = _unitq(_q(pose, 3 + 4 * bones[f, 1]))
    gl = _mul(gu, ql)
    gf = _mul(gl, _unitq(_q(pose, 3 + 4 * bones[f, 2])))
    o = _rot(gh, (offs[f, 0, 0], offs[f, 0, 1], offs[f, 0, 2]))
    hip = (float(pose[0]) + o[0], float(pose[1]) + o[1], float(pose[2]) + o[2])
    k = _rot(gu, (offs[f, 1, 0], offs[f, 1, 1], offs[f, 1, 2]))
    a = _rot(gl, (offs[f, 2, 0], offs[f, 2, 1], offs[f, 2, 2]))
    ankle = (hip[0] + k[0] + a[0], hip[1] + k[1] + a[1], hip[2] + k[2] + a[2])
    heel = _rot(gf, (offs[f, 3, 0], offs[f, 3, 1], offs[f, 3, 2]))
    toe = _rot(gf, (offs[f, 4, 0], offs[f, 4, 1], offs[f, 4, 2]))
    return hip, ankle, heel, toe, gh, gu, gl, gf, ql


@njit(cache=True, nogil=True)
def _leg_target(pose, f, bones, offs, planted, plant, weight, contact, leash, pull, release, plant_rate,
                target):  # pragma: no cover - compiled
    """Leg f's state stepped (plant, release, leash) and its ankle target written to ``target[f]``:
    x, y, z (the dance's ankle, moved by the blend weight towards the plant horizontally) and the
    smoothstepped weight."""
    _, ankle, heel, toe, _, _, _, _, _ = _leg_fk(pose, f, bones, offs)
    ax, ay, az = ankle
    mx, mz = ax + 0.5 * (heel[0] + toe[0]), az + 0.5 * (heel[2] + toe[2])  # the dance's heel-toe midpoint
    w = weight[f]
    if contact[f] > 0.5:
        if planted[f] == 0:  # planted where it is shown now
            if w > 0.0:  # mid-release (between plant and dance): held at once
                e = w * w * (3.0 - 2.0 * w)
                plant[f, 0] = mx + e * (plant[f, 0] - mx)
                plant[f, 2] = mz + e * (plant[f, 2] - mz)
                w = 1.0
            else:  # the dance's foot: the hold grows over plant_rate's frames, the foot slows to it
                plant[f, 0], plant[f, 2] = mx, mz
            planted[f] = 1
        w = min(1.0, w + plant_rate)
    else:
        planted[f] = 0
        w = max(0.0, w - release)
    weight[f] = w
    dx, dz = plant[f, 0] - mx, plant[f, 2] - mz
    if planted[f] == 1:
        d = math.sqrt(dx * dx + dz * dz)
        if d > leash:  # pulled after the dance's foot, by pull of the way past the leash a frame
            k = 1.0 - pull * (d - leash) / d
            plant[f, 0] = mx + dx * k
            plant[f, 2] = mz + dz * k
            dx, dz = plant[f, 0] - mx, plant[f, 2] - mz
    e = w * w * (3.0 - 2.0 * w)
    target[f, 0], target[f, 1], target[f, 2], target[f, 3] = ax + e * dx, ay, az + e * dz, e


@njit(cache=True, nogil=True)
def _leg_ik(pose, f, bones, offs, ang_rest, floor, knee_min, soft, target, knee_max,
            wrap_forward):  # pragma: no cover - compiled
    """Leg f of ``pose`` bent and swung so its ankle reaches ``target[f]`` (a leg of weight 0: its
    own ankle), raised onto the floor, the knee bent forwards by at least ``knee_min``; the foot
    keeps its world orientation. Left bit for bit as it is when there is nothing to do."""
    cu, cl, cf = 3 + 4 * bones[f, 0], 3 + 4 * bones[f, 1], 3 + 4 * bones[f, 2]
    hip, ankle, heel, toe, gh, gu, gl, gf, ql = _leg_fk(pose, f, bones, offs)
    held = target[f, 3] > 0.0
    tx, ty, tz = (target[f, 0], target[f, 1], target[f, 2]) if held else ankle
    lift = floor - (ty + min(heel[1], toe[1]))
    if lift > 0.0:  # onto the floor
        ty += lift
    ok = (offs[f, 1, 0], offs[f, 1, 1], offs[f, 1, 2])  # knee in the thigh's frame
    oa = (offs[f, 2, 0], offs[f, 2, 1], offs[f, 2, 2])  # ankle in the shin's frame
    v = _rot(ql, oa)  # the shin in the thigh's frame
    phi0 = math.atan2(-v[2], -v[1]) - ang_rest[f]  # the knee's flexion now, about the thigh's X axis
    phi0 = (phi0 + math.pi) % (2.0 * math.pi) - math.pi
    if not held and lift <= 0.0 and phi0 >= knee_min:
        return  # nothing to do: the leg as the dance has it
    hx, hy, hz = tx - hip[0], ty - hip[1], tz - hip[2]
    dist = math.sqrt(hx * hx + hy * hy + hz * hz)
    l1sq = ok[0] * ok[0] + ok[1] * ok[1] + ok[2] * ok[2]
    l2sq = oa[0] * oa[0] + oa[1] * oa[1] + oa[2] * oa[2]
    # |ok + Rx(delta) v|^2 = l1^2 + l2^2 + 2 (c0 + p cos delta + q sin delta)
    c0 = ok[0] * v[0]
    p = ok[1] * v[1] + ok[2] * v[2]
    q = -ok[1] * v[2] + ok[2] * v[1]
    r = math.sqrt(p * p + q * q)
    psi = math.atan2(q, p)  # delta that straightens the leg (the longest reach)
    if held and soft > 0.0:  # soft reach: the last `soft` m of the leg's length approached, never met (no snap)
        start = math.sqrt(max(l1sq + l2sq + 2.0 * (c0 + r), 0.0)) - soft
        if dist > start:
            dist = start + soft * (1.0 - math.exp(-(dist - start) / soft))
    c = (0.5 * (dist * dist - l1sq - l2sq) - c0) / max(r, 1e-12)
    alpha = math.acos(min(1.0, max(-1.0, c)))
    if wrap_forward:  # the flexion bent forwards, in [-pi/2, 3pi/2), at most knee_max
        phi1 = (phi0 + psi + alpha + 0.5 * math.pi) % (2.0 * math.pi) - 0.5 * math.pi
        phi1 = min(phi1, knee_max)
    else:  # before: in [-pi, pi), so a fold just past pi wrapped to -pi and the leg snapped straight
        phi1 = (phi0 + psi + alpha + math.pi) % (2.0 * math.pi) - math.pi
    delta = max(phi1, knee_min) - phi0
    h = 0.5 * delta
    rx = (math.sin(h), 0.0, 0.0, math.cos(h))
    ql2 = _mul(rx, ql)
    v2 = _rot(rx, v)
    al = (ok[0] + v2[0], ok[1] + v2[1], ok[2] + v2[2])  # the ankle in the thigh's frame
    aw = _rot(gu, al)
    # the thigh swung (the shortest way) so the ankle points at the target
    na = math.sqrt(aw[0] * aw[0] + aw[1] * aw[1] + aw[2] * aw[2])
    if dist > 1e-9 and na > 1e-9:
        ux, uy, uz = aw[0] / na, aw[1] / na, aw[2] / na
        bx, by, bz = hx / dist, hy / dist, hz / dist
        s = _unitq((uy * bz - uz * by, uz * bx - ux * bz, ux * by - uy * bx, 1.0 + ux * bx + uy * by + uz * bz))
        gu = _mul(s, gu)
    qu2 = _unitq(_mul(_conj(gh), gu))
    gl2 = _mul(gu, ql2)
    qf2 = _unitq(_mul(_conj(gl2), gf))  # the foot keeps its orientation in the world
    for i in range(4):
        pose[cu + i] = qu2[i]
        pose[cl + i] = ql2[i]
        pose[cf + i] = qf2[i]


@njit(cache=True, nogil=True)
def _lowest(pose, f, bones, offs):  # pragma: no cover - compiled
    """The height (m) of the lower of foot f's heel and toe in ``pose``."""
    gh = _unitq(_q(pose, 3))
    gu = _mul(gh, _unitq(_q(pose, 3 + 4 * bones[f, 0])))
    gl = _mul(gu, _unitq(_q(pose, 3 + 4 * bones[f, 1])))
    gf = _mul(gl, _unitq(_q(pose, 3 + 4 * bones[f, 2])))
    y = float(pose[1]) + _rot(gh, (offs[f, 0, 0], offs[f, 0, 1], offs[f, 0, 2]))[1]
    y += _rot(gu, (offs[f, 1, 0], offs[f, 1, 1], offs[f, 1, 2]))[1]
    y += _rot(gl, (offs[f, 2, 0], offs[f, 2, 1], offs[f, 2, 2]))[1]
    return y + min(_rot(gf, (offs[f, 3, 0], offs[f, 3, 1], offs[f, 3, 2]))[1],
                   _rot(gf, (offs[f, 4, 0], offs[f, 4, 1], offs[f, 4, 2]))[1])


@njit(cache=True, nogil=True)
def feet_kernel(pose, bones, offs, ang_rest, planted, plant, weight, ground, target, contact, floor, leash, pull,
                release, knee_min, ground_rate, plant_rate, soft, knee_max=math.pi,
                wrap_forward=True):  # pragma: no cover - compiled
    """Both legs of ``pose`` (P,) float32, in place; the state arrays updated (see :class:`FeetLock`)."""
    if ground_rate > 0.0:  # the body lowered or raised by the exemplar's lift (GROUND_RATE < 1: low-passed twice)
        ground[1] += ground_rate * (contact[2] - ground[1])
        ground[0] += ground_rate * (ground[1] - ground[0])
        pose[1] = pose[1] + ground[0]
    for f in range(2):
        _leg_target(pose, f, bones, offs, planted, plant, weight, contact, leash, pull, release, plant_rate, target)
    for f in range(2):
        _leg_ik(pose, f, bones, offs, ang_rest, floor, knee_min, soft, target, knee_max, wrap_forward)


class FeetLock:
    """The feet part of the stream (see the module docstring): ``step(pose, contact)`` per frame.

    floor: the floor height (m; the memory's, :func:`member_contacts`). The skeleton is the
    default one, as everywhere the stream computes positions.
    """

    def __init__(self, floor: float) -> None:
        skel = load_default_skeleton()
        off, end = skel.offsets, skel.end_offsets
        self.floor = float(floor)
        self._bones = np.array([[BONE_INDEX[f"{s}{b}"] for b in ("UpperLeg", "LowerLeg", "Foot")] for s in _SIDES],
                               np.int64)
        self._offs = np.array([[off[BONE_INDEX[f"{s}UpperLeg"]], off[BONE_INDEX[f"{s}LowerLeg"]],
                                off[BONE_INDEX[f"{s}Foot"]], end[END_SITES.index(f"{s}Heel")],
                                off[BONE_INDEX[f"{s}Toes"]]] for s in _SIDES], np.float64)  # (2, 5, 3)
        shin = self._offs[:, 2]
        self._ang_rest = np.arctan2(-shin[:, 2], -shin[:, 1])  # the straight shin's angle (0 for this rig)
        self._release = 1.0 / max(RELEASE_FRAMES, 1)
        self._plant = 1.0 / max(PLANT_FRAMES, 1)
        self._knee_min = math.radians(KNEE_MIN_DEG)
        self.planted = np.zeros(2, np.int64)
        self.plant = np.zeros((2, 3), np.float64)
        self.weight = np.zeros(2, np.float64)
        self.ground = np.zeros(2, np.float64)  # the body's height offset (m, GROUND_RATE) and its first low-pass
        self._target = np.zeros((2, 4), np.float64)  # each leg's ankle target and weight, this frame
        self._contact = np.zeros(3, np.float64)
        self.reset()

    def reset(self) -> None:
        """No foot planted, nothing to hand back."""
        self.planted[:] = 0
        self.plant[:] = 0.0
        self.weight[:] = 0.0
        self.ground[:] = 0.0

    def step(self, pose: np.ndarray, left: float, right: float, lift: float = 0.0) -> np.ndarray:
        """``pose`` (P,) float32 with its legs put on the floor, in place (and returned); ``left``,
        ``right``: the memory's contact value of each foot at the frame played (0..1); ``lift``:
        the exemplar's lift there (m, :func:`member_contacts`)."""
        self._contact[0], self._contact[1], self._contact[2] = left, right, lift
        feet_kernel(pose, self._bones, self._offs, self._ang_rest, self.planted, self.plant, self.weight, self.ground,
                    self._target, self._contact, self.floor, LEASH, LEASH_PULL, self._release, self._knee_min, GROUND_RATE,
                    self._plant, SOFT_REACH, math.radians(KNEE_MAX_DEG), KNEE_WRAP_FORWARD)
        return pose

    def lift_of(self, pose: np.ndarray) -> float:
        """The lift (m) that puts the lower foot point of ``pose`` (P,) on the floor (the idle's)."""
        p = np.ascontiguousarray(pose, np.float32)
        return self.floor - min(_lowest(p, 0, self._bones, self._offs), _lowest(p, 1, self._bones, self._offs))
