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
- ``ground`` (2,) the body's height offset (the lift, low-passed twice);
- ``shown`` (2, 6), ``legs`` (2, 16), ``rel`` (2, 2, 4): the hand-back in rotation space's
  (:data:`ROTATION_RELEASE`, :func:`_leg_blend`): each leg as shown last frame (ankle; thigh
  and shin local rotations), the leg it turns from, the turns' signs, a replant's carry.

**Every frame, per leg** (one compiled call, :func:`feet_kernel`; 0.037-0.038 ms a frame for
both, p99 0.064-0.069 ms: benchmarks/hop_profile.py, docs/feet.md): the body is grounded; the dance's heel-toe midpoint
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

**A hand-back in rotation space.** A released foot's blended target that comes within
:data:`RELEASE_CLEARANCE` of the hip joint (a dancer kicking the foot up past the hip) would
swing the thigh round; from that frame the leg is no longer aimed at a target: the leg as
shown then (kept in the hips' frame) is turned to the dance's own by the weight left, thigh
and shin by their relative rotations' powers, each keeping its last frame's sign
(:func:`_towards`: a turn past half a turn goes on the same way), the foot at the dance's
world orientation. A foot planted again meanwhile is held where it is shown and carried from
that leg to the planted solution over :data:`REPLANT_FRAMES`. Hand-written quaternion
arithmetic in numba, as the IK, so the live path allocates nothing. Every other release is
handed back as above.
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
#: A released foot whose blended ankle target comes within :data:`RELEASE_CLEARANCE` of the hip
#: joint is handed back in rotation space from there (True): the leg as shown that frame, kept in
#: the hips' frame, turned to the dance's own by the weight left (:func:`_leg_blend`), no target
#: aimed at. False: as before, the target blended on: a dancer kicking the released foot up past
#: the hip took it by the hip joint and the IK's thigh, aimed at it, swung round (94.8 degrees in a
#: frame, the shared sample's library on 3x2; docs/feet.md). Switch for measuring.
ROTATION_RELEASE: bool = True
#: How near the hip joint (m) a released foot's blended ankle target may come before the hand-back
#: goes on in rotation space (a knee folded past ~120 degrees). The shipped model's targets stay
#: further: the validation songs on 6x5 and 3x2 read as before (foot_skating.py, docs/feet.md).
RELEASE_CLEARANCE: float = 0.4
#: Frames over which a foot planted again while handed back in rotation space goes from the leg as
#: shown to the planted solution (smoothstep): that leg is not the IK's, and the planted one would
#: jump to it.
REPLANT_FRAMES: int = 10
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


@njit(cache=True, nogil=True)
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
def _unsoft(pose, f, bones, offs, hip, ankle, soft):  # pragma: no cover - compiled
    """The ankle target (x, y, z) for which leg f's IK, with its soft reach ``soft``
    (:data:`SOFT_REACH`), puts the ankle at ``ankle``: a replant holds the foot where it is shown."""
    hx, hy, hz = ankle[0] - hip[0], ankle[1] - hip[1], ankle[2] - hip[2]
    dist = math.sqrt(hx * hx + hy * hy + hz * hz)
    ok = (offs[f, 1, 0], offs[f, 1, 1], offs[f, 1, 2])
    v = _rot(_unitq(_q(pose, 3 + 4 * bones[f, 1])), (offs[f, 2, 0], offs[f, 2, 1], offs[f, 2, 2]))
    r = math.sqrt((ok[1] * v[1] + ok[2] * v[2]) ** 2 + (ok[2] * v[1] - ok[1] * v[2]) ** 2)
    start = math.sqrt(max(ok[0] * ok[0] + ok[1] * ok[1] + ok[2] * ok[2] + v[0] * v[0] + v[1] * v[1] + v[2] * v[2]
                          + 2.0 * (ok[0] * v[0] + r), 0.0)) - soft
    if soft <= 0.0 or dist <= start or dist < 1e-9:
        return ankle
    far = start - soft * math.log(max(1.0 - (dist - start) / soft, 1e-3))  # the soft reach undone
    k = far / dist
    return hip[0] + hx * k, hip[1] + hy * k, hip[2] + hz * k


@njit(cache=True, nogil=True)
def _leg_target(pose, f, bones, offs, planted, plant, weight, contact, leash, pull, release, plant_rate,
                target, shown, legs, rel, rotation, clearance, carry_rate, soft):  # pragma: no cover - compiled
    """Leg f's state stepped (plant, release, leash) and its ankle target written to ``target[f]``:
    x, y, z (the dance's ankle, moved by the blend weight towards the plant horizontally), the
    blend weight, the mode (0: solved for it, :func:`_leg_ik`; with ``rotation``,
    :data:`ROTATION_RELEASE`: 1, handed back in rotation space, the weight then the share of it left
    since the switch; 2, a replant's carry, x, y, z then the planted target: :func:`_leg_blend`) and
    the carry's weight. ``shown``, ``legs``, ``rel``: see :func:`_leg_blend`."""
    hip, ankle, heel, toe, _, _, _, _, _ = _leg_fk(pose, f, bones, offs)
    ax, ay, az = ankle
    mx, mz = ax + 0.5 * (heel[0] + toe[0]), az + 0.5 * (heel[2] + toe[2])  # the dance's heel-toe midpoint
    w = weight[f]
    c = shown[f, 4]
    if contact[f] > 0.5:
        if planted[f] == 0:  # planted where it is shown now
            if w > 0.0:  # mid-release (between plant and dance): held at once
                if shown[f, 5] > 0.0:  # handed back in rotation space: the planted leg carried in from the leg shown
                    tx, ty, tz = _unsoft(pose, f, bones, offs, hip, (shown[f, 0], shown[f, 1], shown[f, 2]), soft)
                    plant[f, 0], plant[f, 2] = mx + tx - ax, mz + tz - az
                    c, shown[f, 3], shown[f, 5] = 1.0, ty - ay, 0.0
                    legs[f, 0:8] = legs[f, 8:16]
                    rel[f] = 0.0
                else:
                    e = w * w * (3.0 - 2.0 * w)
                    plant[f, 0] = mx + e * (plant[f, 0] - mx)
                    plant[f, 2] = mz + e * (plant[f, 2] - mz)
                w = 1.0
            else:  # the dance's foot: the hold grows over plant_rate's frames, the foot slows to it
                plant[f, 0], plant[f, 2] = mx, mz
            planted[f] = 1
        w = min(1.0, w + plant_rate)
    else:
        if planted[f] == 1 and c > 0.0:  # released while carried in: handed back in rotation space at once
            shown[f, 5] = -1.0
        planted[f] = 0
        w = max(0.0, w - release)
        if w <= 0.0:
            shown[f, 5] = 0.0
    weight[f] = w
    dx, dz = plant[f, 0] - mx, plant[f, 2] - mz
    k = c * c * (3.0 - 2.0 * c)
    shown[f, 4] = 0.0
    if c > 0.0 and planted[f] == 1:  # a replant's carry: its height from the leg shown's to the dance's
        ay += k * shown[f, 3]
        shown[f, 4] = max(0.0, c - carry_rate)
    else:
        k = 0.0
    if planted[f] == 1:
        d = math.sqrt(dx * dx + dz * dz)
        if d > leash:  # pulled after the dance's foot, by pull of the way past the leash a frame (a carry: less)
            s = 1.0 - pull * (1.0 - k) * (d - leash) / d
            plant[f, 0] = mx + dx * s
            plant[f, 2] = mz + dz * s
            dx, dz = plant[f, 0] - mx, plant[f, 2] - mz
    e = w * w * (3.0 - 2.0 * w)
    tx, ty, tz = ax + e * dx, ay, az + e * dz
    mode = 0.0
    if planted[f] == 0 and w > 0.0 and rotation:
        hx, hy, hz = tx - hip[0], ty - hip[1], tz - hip[2]
        if shown[f, 5] < 0.0 or (shown[f, 5] == 0.0 and hx * hx + hy * hy + hz * hz < clearance * clearance):
            shown[f, 5] = e  # the target would pass by the hip: from here on the leg shown turns to the dance's
            legs[f, 0:8] = legs[f, 8:16]
            rel[f] = 0.0
        if shown[f, 5] > 0.0:
            mode, e = 1.0, e / shown[f, 5]
    elif k > 0.0:
        mode, e, tx, tz = 2.0, 1.0, ax + dx, az + dz
    target[f, 0], target[f, 1], target[f, 2], target[f, 3], target[f, 4], target[f, 5] = tx, ty, tz, e, mode, k


@njit(cache=True, nogil=True)
def _leg_solve(pose, f, bones, offs, ang_rest, floor, knee_min, soft, tx, ty, tz, held, knee_max,
               wrap_forward):  # pragma: no cover - compiled
    """Leg f of ``pose`` bent and swung so its ankle reaches (tx, ty, tz) (``held``; not held: its
    own ankle), raised onto the floor, the knee bent forwards by at least ``knee_min``; the foot
    keeps its world orientation. (changed, thigh, shin, foot local rotations); not changed (nothing
    to do): the pose's own."""
    cu, cl, cf = 3 + 4 * bones[f, 0], 3 + 4 * bones[f, 1], 3 + 4 * bones[f, 2]
    hip, ankle, heel, toe, gh, gu, gl, gf, ql = _leg_fk(pose, f, bones, offs)
    if not held:
        tx, ty, tz = ankle
    lift = floor - (ty + min(heel[1], toe[1]))
    if lift > 0.0:  # onto the floor
        ty += lift
    ok = (offs[f, 1, 0], offs[f, 1, 1], offs[f, 1, 2])  # knee in the thigh's frame
    oa = (offs[f, 2, 0], offs[f, 2, 1], offs[f, 2, 2])  # ankle in the shin's frame
    v = _rot(ql, oa)  # the shin in the thigh's frame
    phi0 = math.atan2(-v[2], -v[1]) - ang_rest[f]  # the knee's flexion now, about the thigh's X axis
    phi0 = (phi0 + math.pi) % (2.0 * math.pi) - math.pi
    if not held and lift <= 0.0 and phi0 >= knee_min:  # nothing to do: the leg as the dance has it
        return False, _unitq(_q(pose, cu)), ql, _unitq(_q(pose, cf))
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
    return True, qu2, ql2, qf2


@njit(cache=True, nogil=True)
def _put(pose, f, bones, qu, ql, qf):  # pragma: no cover - compiled
    """Leg f's thigh, shin and foot local rotations written into ``pose``."""
    cu, cl, cf = 3 + 4 * bones[f, 0], 3 + 4 * bones[f, 1], 3 + 4 * bones[f, 2]
    for i in range(4):
        pose[cu + i] = qu[i]
        pose[cl + i] = ql[i]
        pose[cf + i] = qf[i]


@njit(cache=True, nogil=True)
def _leg_ik(pose, f, bones, offs, ang_rest, floor, knee_min, soft, target, knee_max,
            wrap_forward):  # pragma: no cover - compiled
    """Leg f of ``pose`` solved (:func:`_leg_solve`) for its ankle target ``target[f]`` (a leg of
    weight 0: its own ankle), in place; left bit for bit as it is when there is nothing to do."""
    changed, qu, ql, qf = _leg_solve(pose, f, bones, offs, ang_rest, floor, knee_min, soft, target[f, 0],
                                     target[f, 1], target[f, 2], target[f, 3] > 0.0, knee_max, wrap_forward)
    if changed:
        _put(pose, f, bones, qu, ql, qf)


@njit(cache=True, nogil=True)
def _towards(a, b, e, rel, f, k):  # pragma: no cover - compiled
    """Unit quaternion a turned by ``e`` (0: a, 1: b) of the way to b. The turn from a to b,
    ``rel[f, k]`` (its quaternion b a^-1), keeps its sign from the last frame's (all zeros: the
    shorter arc), so a turn passing half a turn goes on the same way instead of flipping round."""
    r = _mul(b, _conj(a))
    last = (rel[f, k, 0], rel[f, k, 1], rel[f, k, 2], rel[f, k, 3])
    d = r[3] if last[0] == 0.0 and last[1] == 0.0 and last[2] == 0.0 and last[3] == 0.0 else \
        r[0] * last[0] + r[1] * last[1] + r[2] * last[2] + r[3] * last[3]
    if d < 0.0:
        r = (-r[0], -r[1], -r[2], -r[3])
    rel[f, k, 0], rel[f, k, 1], rel[f, k, 2], rel[f, k, 3] = r
    sn = math.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])
    if sn < 1e-9:  # no turn (or a whole one, its axis lost): a as it is
        return a
    th = e * math.atan2(sn, r[3])  # e of the half angle, in [0, pi]
    k = math.sin(th) / sn
    return _unitq(_mul((r[0] * k, r[1] * k, r[2] * k, math.cos(th)), a))


@njit(cache=True, nogil=True)
def _leg_blend(pose, f, bones, offs, ang_rest, floor, knee_min, soft, target, knee_max, wrap_forward, shown,
               legs, rel):  # pragma: no cover - compiled
    """Leg f blended in rotation space (:data:`ROTATION_RELEASE`), in place, towards the held leg
    ``legs[f, :8]`` (thigh and shin, local). Handed back (mode 1): from the dance's own leg (floor and
    knee mended) by the weight ``target[f, 3]``, the held leg the one shown when the hand-back
    switched, kept in the hips' frame (nothing aimed: no target to pass by the hip). A replant's
    carry (mode 2): from the planted solution by ``target[f, 5]``, the held leg re-aimed at the same
    target (``target[f]``: the ankle where it was shown, its soft reach undone, :func:`_unsoft`)
    each frame. Thigh and shin turn (:func:`_towards`, ``rel``), the foot keeps the dance's world
    orientation; a blend that would put the heel or toe under the floor is solved once more for its
    own ankle raised onto it. ``shown[f]``: the leg shown last frame's ankle (:func:`_keep_shown`),
    a replant's height offset (m) and carry (1 -> 0), the weight at the switch (-1: switch now)."""
    mode = target[f, 4]
    low = floor if mode == 1.0 else -1e9  # a carry's target lies beyond the ankle (undone soft reach): floor after
    _, du, dl, df = _leg_solve(pose, f, bones, offs, ang_rest, low, knee_min, soft, target[f, 0], target[f, 1],
                               target[f, 2], mode == 2.0, knee_max, wrap_forward)
    gh = _unitq(_q(pose, 3))
    gf = _mul(_mul(_mul(gh, du), dl), df)  # the dance's foot in the world
    hu, hl = _q(legs[f], 0), _q(legs[f], 4)
    if mode == 2.0:  # the carried leg re-aimed at the planted target
        _put(pose, f, bones, hu, hl, _unitq(_mul(_conj(_mul(_mul(gh, hu), hl)), gf)))
        _, hu, hl, _ = _leg_solve(pose, f, bones, offs, ang_rest, low, knee_min, soft, target[f, 0], target[f, 1],
                                  target[f, 2], True, knee_max, wrap_forward)
        for i in range(4):
            legs[f, i], legs[f, 4 + i] = hu[i], hl[i]
    e = target[f, 3] if mode == 1.0 else target[f, 5]
    ou, ol = _towards(du, hu, e, rel, f, 0), _towards(dl, hl, e, rel, f, 1)
    _put(pose, f, bones, ou, ol, _unitq(_mul(_conj(_mul(_mul(gh, ou), ol)), gf)))
    _, ankle, heel, toe, _, _, _, _, _ = _leg_fk(pose, f, bones, offs)
    if ankle[1] + min(heel[1], toe[1]) < floor:
        _, qu, ql, qf = _leg_solve(pose, f, bones, offs, ang_rest, floor, knee_min, soft, ankle[0], ankle[1],
                                   ankle[2], True, knee_max, wrap_forward)
        _put(pose, f, bones, qu, ql, qf)


@njit(cache=True, nogil=True)
def _keep_shown(pose, f, bones, offs, shown, legs):  # pragma: no cover - compiled
    """Leg f as shown kept for a blend that may follow (:func:`_leg_blend`): its ankle in
    ``shown[f, :3]``, thigh and shin (local) in ``legs[f, 8:]``."""
    _, ankle, _, _, _, _, _, _, ql = _leg_fk(pose, f, bones, offs)
    shown[f, 0], shown[f, 1], shown[f, 2] = ankle
    hu = _unitq(_q(pose, 3 + 4 * bones[f, 0]))
    for i in range(4):
        legs[f, 8 + i], legs[f, 12 + i] = hu[i], ql[i]


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
                release, knee_min, ground_rate, plant_rate, soft, knee_max, wrap_forward, shown, legs, rel, rotation,
                clearance, carry_rate):  # pragma: no cover - compiled
    """Both legs of ``pose`` (P,) float32, in place; the state arrays updated (see :class:`FeetLock`).
    ``target`` (2, 6) is scratch; ``shown``, ``legs``, ``rel``: the blends' (``rotation``, :func:`_leg_blend`)."""
    if ground_rate > 0.0:  # the body lowered or raised by the exemplar's lift (GROUND_RATE < 1: low-passed twice)
        ground[1] += ground_rate * (contact[2] - ground[1])
        ground[0] += ground_rate * (ground[1] - ground[0])
        pose[1] = pose[1] + ground[0]
    for f in range(2):
        _leg_target(pose, f, bones, offs, planted, plant, weight, contact, leash, pull, release, plant_rate, target,
                    shown, legs, rel, rotation, clearance, carry_rate, soft)
    for f in range(2):
        if target[f, 4] > 0.0:
            _leg_blend(pose, f, bones, offs, ang_rest, floor, knee_min, soft, target, knee_max, wrap_forward, shown,
                       legs, rel)
        else:
            _leg_ik(pose, f, bones, offs, ang_rest, floor, knee_min, soft, target, knee_max, wrap_forward)
        if rotation and weight[f] > 0.0:  # only a held or released leg can switch or replant next frame
            _keep_shown(pose, f, bones, offs, shown, legs)


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
        self._target = np.zeros((2, 6), np.float64)  # each leg's ankle target, weight, mode, carry, this frame
        self.shown = np.zeros((2, 6), np.float64)  # each leg shown last frame: its ankle (x, y, z);
        #                                            a replant's height offset (m) and carry (1 -> 0)
        self.legs = np.zeros((2, 16), np.float64)  # each leg's held thigh and shin, its shown ones (local quaternions)
        self.rel = np.zeros((2, 2, 4), np.float64)  # a blend's turns from the dance's thigh, shin to the held's
        self._contact = np.zeros(3, np.float64)
        self.reset()

    def reset(self) -> None:
        """No foot planted, nothing to hand back."""
        self.planted[:] = 0
        self.plant[:] = 0.0
        self.weight[:] = 0.0
        self.ground[:] = 0.0
        self.shown[:] = 0.0
        self.legs[:] = 0.0
        self.rel[:] = 0.0

    def step(self, pose: np.ndarray, left: float, right: float, lift: float = 0.0) -> np.ndarray:
        """``pose`` (P,) float32 with its legs put on the floor, in place (and returned); ``left``,
        ``right``: the memory's contact value of each foot at the frame played (0..1); ``lift``:
        the exemplar's lift there (m, :func:`member_contacts`)."""
        self._contact[0], self._contact[1], self._contact[2] = left, right, lift
        feet_kernel(pose, self._bones, self._offs, self._ang_rest, self.planted, self.plant, self.weight, self.ground,
                    self._target, self._contact, self.floor, LEASH, LEASH_PULL, self._release, self._knee_min, GROUND_RATE,
                    self._plant, SOFT_REACH, math.radians(KNEE_MAX_DEG), KNEE_WRAP_FORWARD, self.shown,
                    self.legs, self.rel, ROTATION_RELEASE, RELEASE_CLEARANCE, 1.0 / max(REPLANT_FRAMES, 1))
        return pose

    def lift_of(self, pose: np.ndarray) -> float:
        """The lift (m) that puts the lower foot point of ``pose`` (P,) on the floor (the idle's)."""
        p = np.ascontiguousarray(pose, np.float32)
        return self.floor - min(_lowest(p, 0, self._bones, self._offs), _lowest(p, 1, self._bones, self._offs))
