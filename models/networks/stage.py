"""The stage part of the live dance (issue 39): where the performer stands and which way it faces.

The choreographic memory's poses are canonical: the dancers' travel across the floor and
their heading were taken out for training (models/data/canonical.py). The memory keeps them
beside each exemplar (``DanceVQ.member_travel``, models/training/travel_memory.py): per frame
of its window the root's displacement and heading change since its first frame. The stage
plays them back: :class:`Stage` holds a world position (x, z, metres) and heading (radians
about +Y, 0 = facing the audience at +Z), and every frame

1. reads the playing movement's travel track at the **same fractional position** the player
   reads its pose (:meth:`~models.networks.player.Player.warped`), so the tempo rate, the beat warp and the
   handover's blend move the travel exactly as they move the pose: the track is rebuilt at
   each handover as the pose rows are (the last movement's frames, then the new exemplar's
   travel carried on from where the last one's reached, its velocity blended from the last
   one's, :data:`CARRY_ROWS`), so there is no jump and no kink;
2. turns the step between this frame's and the last frame's read into the performer's own
   frame (forward, sideways, turn) and scales it by ``1 - idle`` (the idle stands still);
3. bends it inside the stage: within :data:`MARGIN` of an edge a step heading out turns the
   performer's heading inwards (at most :data:`STEER_RATE`), and the part of the step
   towards the edge shrinks with the distance left, so the performer never crosses it (a
   smooth slow-down on that axis only: it keeps dancing along the edge, never a teleport);
   Near an edge the next movement is chosen among those whose own travel heads inwards
   (:meth:`Stage.inwards`, :data:`INWARDS`), so the dance turns in before the bend must;
4. with ``facing audience`` pulls the heading back towards +Z (:data:`FACING_TAU`) and damps
   turns away from it past :data:`FACING_CONE`; ``home()`` adds a walk to the centre;
5. writes x, z into ``pose[0]``, ``pose[2]`` and composes the heading onto the Hips' rotation.

Stage ``0`` (no width or depth) switches the part off: the pose is left exactly as the player
made it, in place facing +Z (the behaviour before issue 39; what ``performer evaluate``
measures, against the dancers' canonical motion). Every step is a few float operations in
Python: no allocation beyond the track's rows at a handover, no loop over joints.
"""

from __future__ import annotations

import math

import numpy as np

from models.errors import ConfigError, short_repr
from models.networks.dance_jit import place_travel, reorigin_track
from models.timebase import FPS

#: The stage a screen or a small stage suits (width x depth, metres), which ``performer
#: generate`` uses unless told otherwise; a stream built without a stage dances in place.
DEFAULT_STAGE: tuple[float, float] = (3.0, 2.0)
#: The largest stage side accepted (metres).
MAX_SIDE: float = 100.0
#: Facing modes: "free" turns as the exemplars' dancers did; "audience" dances the turns
#: but comes back to face +Z.
FACING: tuple[str, ...] = ("free", "audience")
#: Distance from an edge (m) within which the stage bends the path inwards, at most this
#: fraction of the stage's half side (a 1x1 stage: 0.2 m).
MARGIN: float = 0.6
MARGIN_FRACTION: float = 0.4
#: Fastest turn (radians a second) the stage adds to bend a path heading out of the stage
#: inwards, at the edge itself (0 at :data:`MARGIN` from it).
STEER_RATE: float = math.radians(120.0)
#: Fastest the root travels on the stage, m/s: a step longer than this a frame is shortened to
#: it (the speed saturates, never stops). The memory's own frames reach 1.69 m/s at their 99.9th
#: percentile (2.4 at most); the tempo rate and the beat warp play them up to 2.5x faster, which
#: took the root to 5 m/s on DANCE_W_5 (the dancer's 99.9th percentile there: 1.96 m/s;
#: benchmarks/studies/stage_travel.py).
MAX_SPEED: float = 1.7
#: Fastest the exemplar's own turn plays (radians a second: two turns a second): a turn faster
#: than this a frame is shortened to it. The tempo rate and the beat warp play the memory's spins
#: up to 2.5x faster: on DANCE_W_5 the Hips then turned 38 degrees a frame at their 99.9th
#: percentile (42.6 at most) where the dancer's own Hips turn 18.3 (DANCE_C_2's cha-cha 31.6).
MAX_TURN: float = math.radians(720.0)
#: Rows (exemplar frames) over which a new movement's travel takes over the last one's velocity,
#: root (CARRY_ROWS, as the pose's inertialization carries the bones': dance_stream DECAY_FRAMES)
#: and heading (CARRY_TURN_ROWS). Without a carry the root's mean acceleration in the two frames
#: after a handover was 1.5-1.9x that of the movement's last four, the heading's 1.4-1.8x; with
#: 16 and 4 rows 0.8-1.0x and 0.7-1.1x, turns/min 0.93-1.16x the dancers' (16 rows for the
#: heading too: 1.5-1.7x, the last movement's spin carried on; DANCE_W_5, R_5, C_2 on 6x5).
CARRY_ROWS: float = 16.0
CARRY_TURN_ROWS: float = 4.0
#: Near an edge (within :data:`MARGIN`) the movement chosen next is one whose own travel heads
#: inwards where the drawn codes have any (:meth:`Stage.inwards`), so the path turns in by the
#: dance's choice before the stage has to bend it (False: only the bend).
INWARDS: bool = True
#: facing audience: time constant (s) of the pull of the heading back to +Z.
FACING_TAU: float = 0.5
#: facing audience: beyond this angle from +Z (radians) turns further away are damped,
#: to nothing at twice it. Swept on DANCE_W_5, R_5 and C_2 (6x5 stage): tau 0.5 s and 30
#: degrees kept 0.43-0.53x the dancers' turns with 87-93 % of the dancing frames within 45
#: degrees of +Z; at 1.0 s and 45 degrees 0.54-0.60x and 62-77 %. 35 degrees since the fold's hold
#: (issue 43) left 30 at 0.398x on the six validation songs (6x5): 0.42x, 91.7 % within 45 degrees
#: (shared music 83.5 %; benchmarks/studies/stage_travel.py, docs/stage.md).
FACING_CONE: float = math.radians(35.0)
#: home(): walking speed (m/s) back to the centre, the time (s) it takes to reach it, and the
#: distance (m) at which it has arrived.
HOME_SPEED: float = 0.6
HOME_RAMP: float = 0.5
HOME_DONE: float = 0.02
#: :func:`~models.networks.dance_jit.place_travel`'s "no travel" (a movement in place).
_NO_TRAVEL = np.zeros((0, 3))


def parse_stage(value) -> tuple[float, float]:
    """``"WxD"`` (metres, e.g. ``"3x2"``), ``"0"`` / 0 (in place) or a (width, depth) pair ->
    (width, depth); ConfigError with one line otherwise."""
    if isinstance(value, str) and len(value) > 32:
        parts = None
    elif isinstance(value, (tuple, list)) and len(value) == 2:
        parts = list(value)
    elif isinstance(value, (int, float)) and not isinstance(value, bool):
        parts = [value, value] if value == 0 else None
    elif isinstance(value, str):
        text = value.strip().lower()
        parts = [0, 0] if text in ("0", "off", "none") else text.split("x")
    else:
        parts = None
    try:
        if parts is None or len(parts) != 2:
            raise ValueError
        w, d = float(parts[0]), float(parts[1])
    except (TypeError, ValueError):
        raise ConfigError(f"stage must be WxD in metres (e.g. 3x2) or 0 (in place), got {short_repr(value)}") from None
    if w == 0 and d == 0:
        return 0.0, 0.0
    if not (0 < w <= MAX_SIDE and 0 < d <= MAX_SIDE):  # NaN fails too
        raise ConfigError(f"stage sides must be in (0, {MAX_SIDE:g}] m (or the stage 0: in place), "
                          f"got {short_repr(value)}")
    return w, d


def check_facing(mode) -> str:
    """``mode`` if it is one of :data:`FACING`, else ConfigError."""
    if mode not in FACING:
        raise ConfigError(f"facing must be one of {', '.join(FACING)}, got {short_repr(mode)}")
    return mode


def cached_travel(model, sigma: float) -> np.ndarray:
    """``model.member_travel`` (K, M, 2 seg, 3) as float64, low-passed along its frames by a
    Gaussian of ``sigma`` frames as the exemplars' poses are (dance_stream.MEMBER_SMOOTH) and
    put back to 0 at frame 0; kept on the model (streams only read it), recomputed when the
    buffer changes."""
    t = model.member_travel
    key = (t.data_ptr(), t._version, tuple(t.shape), sigma)
    cached = getattr(model, "_travel_cache", None)
    if cached is None or cached[0] != key:
        tr = t.float().numpy().astype(np.float64)
        if sigma > 0.0 and tr.size:
            from scipy.ndimage import gaussian_filter1d

            tr = gaussian_filter1d(tr, sigma, axis=2, mode="nearest")
            tr -= tr[:, :, :1]
        cached = (key, tr)
        model._travel_cache = cached
    return cached[1]


def _wrap(a: float) -> float:
    """``a`` in [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


class Stage:
    """World position and heading of one performer on a ``width`` x ``depth`` m stage (see the
    module docstring). State: :attr:`x`, :attr:`z` (m), :attr:`heading` (rad, 0 facing +Z),
    the playing movement's travel track (``4 seg`` rows of x, z, heading in its own frame),
    where it was last read, and :attr:`counts` (edge frames and choices, for measuring). ``reset()`` puts the performer at the centre facing +Z; the stage
    and facing are settings and survive it."""

    def __init__(self, seg: int, stage=0, facing: str = "free") -> None:
        self.seg = int(seg)
        self.width, self.depth = parse_stage(stage)
        self.facing = check_facing(facing)
        self._track = np.zeros((4 * self.seg, 3), np.float64)  # up to 2 seg rows of the last movement, its window
        # the handover's velocity carry: row f of a new movement moves by carry[f] times the
        # difference of the last movement's velocity and the new one's where they meet
        # (:data:`CARRY_ROWS`: the old velocity blended into the new by a smoothstep, integrated)
        k = np.arange(2 * self.seg, dtype=np.float64)[:, None]
        x = np.clip(k / np.maximum([[CARRY_ROWS, CARRY_ROWS, CARRY_TURN_ROWS]], 1e-9), 0.0, 1.0)
        fade = 1.0 - x * x * (3.0 - 2.0 * x)  # (2 seg, 3): x, z, heading
        self._carry = np.concatenate([np.zeros((1, 3)), np.cumsum(fade, axis=0)[:-1]])
        self.reset()

    # -- settings (a control thread may call them: they only store values) ---------------
    def set_stage(self, stage) -> None:
        """The stage's width and depth (``"WxD"`` m, or 0: in place); ConfigError on a bad value."""
        self.width, self.depth = parse_stage(stage)

    def set_facing(self, facing: str) -> None:
        """``"free"`` or ``"audience"``; ConfigError otherwise."""
        self.facing = check_facing(facing)

    def home(self) -> None:
        """Walk back to the centre of the stage (then dance on from there)."""
        self._homing = True

    @property
    def active(self) -> bool:
        """The stage has a size: travel and turns are played."""
        return self.width > 0.0 and self.depth > 0.0

    @property
    def homing(self) -> bool:
        """Walking back to the centre after :meth:`home`."""
        return self._homing

    def reset(self) -> None:
        """Centre of the stage, facing +Z, nothing playing."""
        self.x = self.z = self.heading = 0.0
        self._track[:] = 0.0
        self._prev: tuple[float, float, float] | None = None  # the track's value read last frame
        self._read = 0.0  # where it was read
        self._ahead: tuple | None = None  # (at, rows, base) of the next handover, read ahead (read_ahead)
        self._homing = False
        self._home_w = 0.0
        # counts for measuring (benchmarks/studies/stage_travel.py): frames near an edge and those
        # the stage bent; movements chosen near an edge and those whose own travel heads inwards
        self.counts = {"edge_frames": 0, "steered_frames": 0, "edge_choices": 0, "inward_choices": 0}

    # -- the player's side ---------------------------------------------------------------
    def handover(self, at: float, travel: np.ndarray | None, first: bool, lead: int | None = None) -> None:
        """A new movement starts (``Player.play``): the track's first ``lead`` rows (``seg``
        unless told; up to ``2 seg``, :mod:`models.networks.handover`) become the last movement's
        at ``at + i`` (as the pose rows do), then ``travel`` (2 seg, 3: the exemplar's
        displacement and heading change from its frame 0, or None: in place) carried on from the
        last movement's value at ``at + lead``. ``first``: nothing played before (the rows before
        are the new movement's first)."""
        tr, s = self._track, (self.seg if lead is None else int(lead))
        near = self._near() if self.active and not first else None
        if near is not None:  # counted: a movement chosen near an edge, and whether its own travel heads inwards
            self.counts["edge_choices"] += 1
            if travel is not None:
                ch, sh = math.cos(self.heading), math.sin(self.heading)
                mx, mz = float(travel[self.seg, 0]), float(travel[self.seg, 1])
                self.counts["inward_choices"] += (mx * ch + mz * sh) * near[0] + (-mx * sh + mz * ch) * near[1] >= -1e-6
        ahead, self._ahead = self._ahead, None
        if first:
            tr[:s] = 0.0
            base = (0.0, 0.0, 0.0)
        else:
            if ahead is not None and ahead[0] == at and len(ahead[1]) == s:  # read the frame before: the same rows
                tr[:s] = ahead[1]
                base = ahead[2]
            else:
                for i in range(s):
                    tr[i] = self._at(at + i)
                base = self._at(at + s)
            self._read -= at  # the last read, in the new rows
        c, sn = math.cos(base[2]), math.sin(base[2])
        # rows s .. s + 2 seg: Ry(base heading) applied to the exemplar's own-frame displacement (or base
        # in place), then, but for the first, the last movement's velocity where they meet blended into
        # the new one's (from the last movement's row at at + lead - 1); the rows after repeat the last
        place_travel(tr, s, 2 * self.seg, *base, c, sn,
                     _NO_TRAVEL if travel is None else np.ascontiguousarray(travel, np.float64), self._carry, not first)
        if self._prev is not None and not first:  # keep the numbers small: the last read is the new origin
            p = self._at(self._read)
            reorigin_track(tr, *p, math.cos(p[2]), math.sin(p[2]))
            self._prev = (0.0, 0.0, 0.0)

    def read_ahead(self, at: float, lead: int) -> None:
        """On the frame before a code step: the track's rows :meth:`handover` (``at``, ``lead``) will
        read, read now (no frame writes the track before it), so the code step only copies them.
        A handover at another row or lead reads its own."""
        rows = [self._at(at + i) for i in range(lead)] if at >= 0.0 else []  # at >= 0: no row read is one written
        self._ahead = (at, rows, self._at(at + lead)) if rows else None

    def _at(self, x: float) -> tuple[float, float, float]:
        """The track at fractional row ``x`` (linear between rows, as warp_pose reads the root)."""
        tr = self._track
        i = min(max(int(math.floor(x)), 0), len(tr) - 2)
        f = x - i
        a, b = tr[i], tr[i + 1]
        return (float(a[0] + f * (b[0] - a[0])), float(a[1] + f * (b[1] - a[1])), float(a[2] + f * (b[2] - a[2])))

    def step(self, pose: np.ndarray, read: float, idle: float) -> None:
        """Advance one frame and place ``pose`` (P,) on the stage, in place: ``read`` the
        fractional row the player read this frame's pose at, ``idle`` the idle fade (0
        dancing .. 1 idle: the travel scaled by ``1 - idle``). Stage 0: ``pose`` untouched
        (set live while away from the centre: first a walk back to it, turning to face +Z)."""
        v = self._at(read)
        p = self._prev if self._prev is not None else v
        self._prev, self._read = v, read
        leaving = not self.active
        if leaving and self.x == 0.0 and self.z == 0.0 and self.heading == 0.0:
            return
        # this frame's step in the movement's own frame at the last read: forward z, sideways x, turn
        c, s = math.cos(p[2]), math.sin(p[2])
        dx, dz = v[0] - p[0], v[1] - p[1]
        keep = 0.0 if leaving else 1.0 - idle
        lx, lz, turn = (c * dx - s * dz) * keep, (s * dx + c * dz) * keep, (v[2] - p[2]) * keep
        turn = min(max(turn, -MAX_TURN / FPS), MAX_TURN / FPS)  # no faster than MAX_TURN
        if self._homing:  # walk back to the centre instead of travelling
            lx = lz = 0.0
        h = self.heading
        ch, sh = math.cos(h), math.sin(h)
        wx, wz = lx * ch + lz * sh, -lx * sh + lz * ch  # Ry(heading): the step on the stage
        fast = math.hypot(wx, wz) * FPS / MAX_SPEED
        if fast > 1.0:  # no faster than MAX_SPEED
            wx, wz = wx / fast, wz / fast
        wx, wz = self._home_step(wx, wz)
        if not leaving:
            wx, wz, steer = self._bound(wx, wz)
            if self._near() is not None:
                self.counts["edge_frames"] += 1
                self.counts["steered_frames"] += steer != 0.0
            turn += steer
        if self.facing == "audience" or leaving:
            turn = self._face_audience(turn)
        self.x += wx
        self.z += wz
        self.heading = h + turn
        if leaving and math.hypot(self.x, self.z) < 1e-3 and abs(_wrap(self.heading)) < 1e-3:
            self.x = self.z = self.heading = 0.0  # back at the centre (under a millimetre): in place from here
            self._homing = False
        pose[0], pose[2] = self.x, self.z
        half = 0.5 * self.heading
        c, s = math.cos(half), math.sin(half)
        qx, qy, qz, qw = float(pose[3]), float(pose[4]), float(pose[5]), float(pose[6])
        pose[3], pose[4], pose[5], pose[6] = c * qx + s * qz, c * qy + s * qw, c * qz - s * qx, c * qw - s * qy

    def _home_step(self, wx: float, wz: float) -> tuple[float, float]:
        """The walk to the centre after :meth:`home` (eased in over :data:`HOME_RAMP`, slowing
        to arrive), added to the step (wx, wz); the stage outside a smaller one set live walks
        the same way to its nearest point inside."""
        hx, hz = 0.5 * self.width, 0.5 * self.depth
        tx, tz = (0.0, 0.0) if self._homing else (min(max(self.x, -hx), hx), min(max(self.z, -hz), hz))
        ex, ez = tx - self.x, tz - self.z
        dist = math.hypot(ex, ez)
        if not self._homing and dist == 0.0:
            self._home_w = 0.0
            return wx, wz
        if self._homing and dist < HOME_DONE and self.active:
            self._homing, self._home_w = False, 0.0
            return wx, wz
        self._home_w = min(1.0, self._home_w + 1.0 / (HOME_RAMP * FPS))
        speed = min(HOME_SPEED / FPS * self._home_w, dist / (HOME_RAMP * FPS))
        return wx + speed * ex / max(dist, 1e-9), wz + speed * ez / max(dist, 1e-9)

    def _near(self) -> tuple[float, float] | None:
        """The inward normal (nx, nz) the near edges add up to, each weighted 0 at :data:`MARGIN`
        from it .. 1 at it; None where no edge is that near."""
        hx, hz = 0.5 * self.width, 0.5 * self.depth
        mx, mz = min(MARGIN, MARGIN_FRACTION * hx), min(MARGIN, MARGIN_FRACTION * hz)
        nx = min(max(1.0 - (self.x + hx) / mx, 0.0), 1.0) - min(max(1.0 - (hx - self.x) / mx, 0.0), 1.0)
        nz = min(max(1.0 - (self.z + hz) / mz, 0.0), 1.0) - min(max(1.0 - (hz - self.z) / mz, 0.0), 1.0)
        return None if nx == 0.0 and nz == 0.0 else (nx, nz)

    def inwards(self, moves) -> np.ndarray | None:
        """Which candidate movements head inwards here: ``moves`` (n, 2; an array or (x, z) pairs) each
        one's own travel over a movement (x, z m, in its own frame: ``member_travel[c, j, seg, :2]``) ->
        (n,) bool, True where it (turned by the heading) moves no further towards a near edge; None where
        no edge is near, :data:`INWARDS` is off, or none heads inwards (then any may play)."""
        n = self._near() if self.active and INWARDS and not self._homing else None
        if n is None:
            return None
        ch, sh = math.cos(self.heading), math.sin(self.heading)
        keep = [(mx * ch + mz * sh) * n[0] + (-mx * sh + mz * ch) * n[1] >= -1e-6  # along the edge counts (a
                for mx, mz in moves]  # micrometre of rounding); a few moves: Python floats, no NumPy call each
        return np.array(keep) if any(keep) else None

    def _bound(self, wx: float, wz: float) -> tuple[float, float, float]:
        """(the step (wx, wz) with its part towards a near edge shrunk, the heading turn that
        bends a path heading out of the stage inwards)."""
        hx, hz = 0.5 * self.width, 0.5 * self.depth
        mx, mz = min(MARGIN, MARGIN_FRACTION * hx), min(MARGIN, MARGIN_FRACTION * hz)
        nx, nz = self._near() or (0.0, 0.0)  # the inward normal of the near edges
        steer = 0.0
        speed = math.hypot(wx, wz)
        if speed > 0.0 and (nx != 0.0 or nz != 0.0):
            out = -(wx * nx + wz * nz) / speed  # > 0: heading out, up to |n|
            if out > 0.0:
                # turning the heading by d turns the step (wx, wz) by Ry(d): d/dd (step . n) = wz nx - wx nz
                side = 1.0 if wz * nx - wx * nz >= 0.0 else -1.0
                steer = side * min(1.0, out) * STEER_RATE / FPS
        # the step towards an edge shrinks with the distance left to it: never crosses it
        if wx > 0.0:
            wx *= min(max((hx - self.x) / mx, 0.0), 1.0)
        elif wx < 0.0:
            wx *= min(max((self.x + hx) / mx, 0.0), 1.0)
        if wz > 0.0:
            wz *= min(max((hz - self.z) / mz, 0.0), 1.0)
        elif wz < 0.0:
            wz *= min(max((self.z + hz) / mz, 0.0), 1.0)
        return wx, wz, steer

    def _face_audience(self, turn: float) -> float:
        """``turn`` with turns away from +Z damped past :data:`FACING_CONE` and the pull back
        towards it (:data:`FACING_TAU`) added."""
        off = _wrap(self.heading)
        if turn * off > 0.0:  # turning further away
            turn *= min(max(2.0 - abs(off) / FACING_CONE, 0.0), 1.0)
        return turn - off / (FACING_TAU * FPS)


# -- an ensemble's spots (issue 39): each performer its own part of one stage --------------------

#: Least distance (m) between two performers' roots in an ensemble: about a body's width.
MIN_SEPARATION: float = 0.6


def ensemble_spots(stage, count: int, gap: float = MIN_SEPARATION) -> list[tuple[float, float, float, float]]:
    """Each of ``count`` performers' spot on one ``stage`` ("WxD" m or 0): (centre x, centre z,
    width, depth) m. The stage is cut into a grid of cells (the columns and rows whose narrowest
    spot is widest), and each cell gives up ``gap / 2`` on every side it shares with another, so
    two performers who each stay inside their own spot are always at least ``gap`` apart.
    Performer i takes column ``i % cols``, row ``i // cols`` (row 0 at the back, -z). Stage 0:
    every spot is (0, 0, 0, 0), in place. ConfigError (one line) when a spot would be empty."""
    w, d = parse_stage(stage)
    count = int(count)
    if count < 1:
        raise ConfigError(f"an ensemble needs at least one performer, got {count}")
    if w == 0.0:
        return [(0.0, 0.0, 0.0, 0.0)] * count
    best = None
    for cols in range(1, count + 1):
        rows = -(-count // cols)
        narrow = min(w / cols - (gap if cols > 2 else gap / 2 if cols == 2 else 0.0),
                     d / rows - (gap if rows > 2 else gap / 2 if rows == 2 else 0.0))
        key = (round(narrow, 9), -(cols * rows - count))
        if best is None or key > best[0]:
            best = (key, cols, rows)
    (narrow, _), cols, rows = best
    if narrow <= 0.0:
        raise ConfigError(f"a {w:g}x{d:g} m stage has no room for {count} performers {gap:g} m apart; "
                          "give a larger stage or 0 (in place)")

    def span(k: int, n: int, side: float) -> tuple[float, float]:
        lo, hi = -side / 2 + k * side / n, -side / 2 + (k + 1) * side / n
        return lo + (gap / 2 if k > 0 else 0.0), hi - (gap / 2 if k < n - 1 else 0.0)

    spots = []
    for i in range(count):
        (x0, x1), (z0, z1) = span(i % cols, cols, w), span(i // cols, rows, d)
        spots.append((0.5 * (x0 + x1), 0.5 * (z0 + z1), x1 - x0, z1 - z0))
    return spots


class SpotStage(Stage):
    """One ensemble performer's :class:`Stage`: its spot of the whole stage (:func:`ensemble_spots`,
    performer ``index`` of ``count``). It is a Stage of the spot's size (so the bound, the facing
    and ``home()`` act within the spot: home is the spot's centre) whose place is moved to the
    spot's centre. State beyond Stage's: :attr:`whole` (width, depth of the whole stage, m) and
    the spot's centre :attr:`cx`, :attr:`cz` (m). ``set_stage`` takes the whole stage: the
    spot is cut anew, and a performer outside its new spot walks into it (as on a Stage made
    smaller live), from where it stood."""

    def __init__(self, seg: int, stage=0, facing: str = "free", spot: tuple[int, int] = (0, 1)) -> None:
        self.index, self.count = int(spot[0]), int(spot[1])
        if not 0 <= self.index < self.count:
            raise ConfigError(f"performer {self.index} of {self.count} has no spot")
        self.whole = parse_stage(stage)
        self.cx, self.cz, w, d = ensemble_spots(self.whole, self.count)[self.index]
        super().__init__(seg, (w, d), facing)

    def set_stage(self, stage) -> None:
        """The whole stage (``"WxD"`` m, or 0: in place); this performer's spot is cut from it."""
        whole = parse_stage(stage)
        cx, cz, w, d = ensemble_spots(whole, self.count)[self.index]  # raises before anything changes
        self.x += self.cx - cx  # where it stands, relative to the new spot's centre
        self.z += self.cz - cz
        self.whole, self.cx, self.cz = whole, cx, cz
        super().set_stage((w, d))

    def step(self, pose: np.ndarray, read: float, idle: float) -> None:
        """:meth:`Stage.step` in the spot, then the spot's centre added to ``pose``'s x, z."""
        super().step(pose, read, idle)
        pose[0] += self.cx
        pose[2] += self.cz

    def state(self) -> dict:
        """What a viewer draws: the whole stage, the facing, this performer's spot and every
        performer's (``spots``, in performer order), each [centre x, centre z, width, depth] m."""
        return {"stage": [float(self.whole[0]), float(self.whole[1])], "facing": str(self.facing),
                "spot": [float(self.cx), float(self.cz), float(self.width), float(self.depth)],
                "spots": [[float(v) for v in s] for s in ensemble_spots(self.whole, self.count)]}
