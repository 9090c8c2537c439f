"""The body moving: a box with the body's principal moments and its principal axes, turning as a trajectory
says, beside the reference's.

``rbcheck check TRAJ --scenario S --animate FILE`` (:func:`write_check_animation`) writes a GIF with
matplotlib's PillowWriter, or an MP4/WebM with its FFMpegWriter where ffmpeg is installed: the reference on
the left, the file on the right over the reference's box drawn faint, the time and the current error in the
frame. A scenario page of the report carries the same picture as data (:func:`report_animation`: a few
hundred quaternions per run, drawn by a short script in the page, so it works offline and in a
``--self-contained`` report) for the reference and the variants the reader picks.

Frames are sampled uniformly in time, at most MAX_FRAMES whatever the run's length (the nearest recorded
row to each frame time; the report's from its ≤ 500-point series, interpolated); the caption says the
sampling. The box is drawn about its centre of mass: the picture is the rotation.
"""
from __future__ import annotations

import base64
import math
import os
from pathlib import Path

import numpy as np

from reference_sim.quaternion import matrix_from_quat, sign_continuous
from reports.polhode import principal_frame

__all__ = ["MAX_FRAMES", "REPORT_FRAMES", "FPS", "AnimationError", "check_animation_path", "box_half_extents",
           "frame_indices", "orientation_error_rad", "write_check_animation", "report_animation"]

#: Frames of ``check --animate`` at most (a 10 s run at Δt = 1e-4 s is 100 000 rows: sampled in time).
MAX_FRAMES = 200
#: Frames of a report page's animation at most (its data is in the page: small).
REPORT_FRAMES = 160
#: Frames per second of the written file.
FPS = 20
#: The thinnest side of the drawn box, as a fraction of its longest (a flat body is still a box).
MIN_SIDE_FRACTION = 0.08
#: Formats by the output file's extension, and the matplotlib writer each needs.
WRITERS = {".gif": "pillow", ".mp4": "ffmpeg", ".webm": "ffmpeg"}
_AXIS_COLOURS = ("#d62728", "#2ca02c", "#1f77b4")
#: The camera of every animation (elevation, azimuth, degrees), world axes: z up.
CAMERA = (20.0, 35.0)
# the faces of a box whose corners are numbered by their signs (bit 0: x, 1: y, 2: z; set = +)
FACES = ((0, 1, 3, 2), (4, 5, 7, 6), (0, 1, 5, 4), (2, 3, 7, 6), (0, 2, 6, 4), (1, 3, 7, 5))


class AnimationError(ValueError):
    """An animation that cannot be written: the message names what is missing and what works."""


def check_animation_path(path) -> str:
    """The matplotlib writer for ``path`` ("pillow" or "ffmpeg"); AnimationError (one line: what is
    missing, and that GIF works) for an unknown extension or an MP4/WebM without ffmpeg."""
    from matplotlib import animation
    suffix = Path(path).suffix.lower()
    writer = WRITERS.get(suffix)
    if writer is None:
        raise AnimationError(f"--animate {path}: unknown format {suffix or '(no extension)'!r}; write "
                             f"{', '.join(WRITERS)} (.gif always works; .mp4 and .webm need ffmpeg)")
    if not animation.writers.is_available(writer):
        need = "ffmpeg (not found on PATH)" if writer == "ffmpeg" else "Pillow"
        raise AnimationError(f"--animate {path}: {suffix[1:].upper()} needs {need}; "
                             f"write a .gif instead (matplotlib's PillowWriter, always available)")
    return writer


def box_half_extents(moments, mass_kg) -> np.ndarray:
    """Half sides (m) along the principal axes of the uniform box of mass ``mass_kg`` with principal
    ``moments`` (kg m², ascending): side_i² = 6 (I_j + I_k − I_i)/m; the thinnest at least
    MIN_SIDE_FRACTION of the longest (a lamina, I₁ + I₂ = I₃, is drawn as a thin plate)."""
    m = np.asarray(moments, dtype=float)
    sq = 6.0 * (m.sum() - 2.0 * m) / float(mass_kg)
    side = np.sqrt(np.clip(sq, 0.0, None))
    longest = float(side.max()) if side.max() > 0 else 1.0
    return 0.5 * np.maximum(side, MIN_SIDE_FRACTION * longest)


def axis_lengths(half) -> np.ndarray:
    """How far each drawn principal axis reaches (m): out of the box, and never shorter than 0.75 of the
    longest half side (the normal of a thin plate stays visible)."""
    half = np.asarray(half, dtype=float)
    return np.maximum(1.45 * half, 0.75 * half.max())


def _corners(half) -> np.ndarray:
    """The 8 corners (principal axes) of a box of half sides ``half``, numbered as FACES expects."""
    return np.array([[(1 if k & 1 else -1) * half[0], (1 if k & 2 else -1) * half[1],
                      (1 if k & 4 else -1) * half[2]] for k in range(8)], dtype=float)


def frame_indices(t_s, n_max: int) -> np.ndarray:
    """Indices of at most ``n_max`` rows spread uniformly in time over ``t_s`` (the row nearest each frame
    time; first and last included; no row twice)."""
    t = np.asarray(t_s, dtype=float)
    if len(t) <= n_max:
        return np.arange(len(t))
    want = np.linspace(t[0], t[-1], n_max)
    k = np.clip(np.searchsorted(t, want), 1, len(t) - 1)
    k = np.where(np.abs(t[k - 1] - want) <= np.abs(t[k] - want), k - 1, k)
    return np.unique(k)


def orientation_error_rad(q, q_ref) -> np.ndarray:
    """The angle (rad) of the rotation between unit quaternions ``q`` and ``q_ref`` (n, 4; w, x, y, z)."""
    q = np.asarray(q, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    r = np.asarray(q_ref, dtype=float)
    r = r / np.linalg.norm(r, axis=-1, keepdims=True)
    c = np.abs(np.sum(q * r, axis=-1))
    return 2.0 * np.arccos(np.clip(c, 0.0, 1.0))


def _camera():
    from reports.polhode import camera as cam
    return cam(CAMERA)


class _BoxArtist:
    """The matplotlib artists of one box on one axes: 6 faces (painter-sorted each frame), its three
    principal axes, and ω."""

    def __init__(self, ax, half, axes_B, colour, ghost=False):
        from matplotlib.patches import Polygon
        self.corners_B = _corners(half) @ axes_B.T          # body axes
        self.axis_tips_B = (axes_B * axis_lengths(half)).T   # rows: each principal axis's tip
        self.right, self.up, self.toward = _camera()
        alpha = 0.0 if ghost else 0.32
        edge = "#9a9a9a" if ghost else "#333333"
        self.faces = [ax.add_patch(Polygon(np.zeros((4, 2)), closed=True, fc=colour, alpha=None,
                                           ec=edge, lw=0.8 if ghost else 1.0,
                                           ls="--" if ghost else "-"))
                      for _ in FACES]
        for f in self.faces:
            f.set_facecolor((*_rgb(colour), alpha))
        self.axes = [] if ghost else [ax.plot([], [], color=c, lw=2.2, solid_capstyle="round")[0]
                                      for c in _AXIS_COLOURS]
        self.ghost = ghost

    def update(self, R, zbase=2.0):
        P = self.corners_B @ R.T
        x, y, d = P @ self.right, P @ self.up, P @ self.toward
        depth = [float(np.mean(d[list(f)])) for f in FACES]
        for k, (patch, f) in enumerate(zip(self.faces, FACES)):
            patch.set_xy(np.column_stack([x[list(f)], y[list(f)]]))
            patch.set_zorder(zbase + 0.01 * (np.argsort(np.argsort(depth))[k]))
        tips = self.axis_tips_B @ R.T
        for i, line in enumerate(self.axes):
            line.set_data([0.0, tips[i] @ self.right], [0.0, tips[i] @ self.up])
            line.set_zorder(zbase + (0.1 if tips[i] @ self.toward >= 0 else -0.1))
        return [*self.faces, *self.axes]


def _rgb(colour):
    from matplotlib.colors import to_rgb
    return to_rgb(colour)


def _panel(ax, extent, title):
    ax.set_xlim(-extent, extent)
    ax.set_ylim(-extent * 0.82, extent * 0.82)
    ax.set_aspect("equal")
    ax.set_axis_off()
    ax.set_title(title, fontsize=10)


def _sampling_words(t_s, idx, dt_rows) -> str:
    n = len(idx)
    span = float(t_s[idx[-1]] - t_s[idx[0]]) if n > 1 else 0.0
    every = span / (n - 1) if n > 1 else 0.0
    return (f"{n} frames, one every {every:.3g} s of the run's {span:.3g} s (uniform in time; the recorded "
            f"row nearest each frame time; rows every {dt_rows:.3g} s), {FPS} frames/s")


def write_check_animation(path, result, scenario) -> dict:
    """Write ``result``'s (a CheckResult) motion beside the scenario's reference to ``path`` (GIF/MP4/WebM,
    :func:`check_animation_path`), atomically (a temporary file in the same folder, renamed when complete:
    never a half-written file). A run that diverged is animated up to its divergence and its last frame
    says so. Returns {"frames": n, "caption": the sampling in words}."""
    from matplotlib import animation

    from reports.canvas import new_figure
    writer_name = check_animation_path(path)
    s = result.series
    if "orientation" not in s["present"]:
        raise AnimationError(f"--animate: {result.source} has no orientation columns (qw, qx, qy, qz): "
                             "there is no motion of the body to draw")
    t = np.asarray(s["t_s"], dtype=float)
    y, y_ref = np.asarray(s["y"], dtype=float), np.asarray(s["y_ref"], dtype=float)
    with np.errstate(all="ignore"):
        q_norm = np.linalg.norm(y[:, 6:10], axis=1)
        bad = ~np.all(np.isfinite(y[:, 6:10]), axis=1) | ~(q_norm > 0) | np.any(np.abs(y) > 1e8, axis=1)
    end = int(np.flatnonzero(bad)[0]) if bad.any() else len(t)
    diverged_at = float(t[end]) if end < len(t) else None
    stopped = [x for x in (result.input.get("diverged_at_s"), result.input.get("lost_orientation_at_s"))
               if x is not None]   # the check dropped the rows from there
    if stopped:
        diverged_at = min([*stopped, *([diverged_at] if diverged_at is not None else [])])
    if end < 1:
        raise AnimationError(f"--animate: {result.source}: the first row's orientation is not finite")
    idx = frame_indices(t[:end], MAX_FRAMES)
    moments, axes_B = principal_frame(scenario.problem.body.inertia_B)
    half = box_half_extents(moments, scenario.problem.body.mass_kg)
    q = sign_continuous(y[idx, 6:10] / q_norm[idx, None])
    q_r = sign_continuous(y_ref[idx, 6:10], q[0])
    R, R_ref = matrix_from_quat(q), matrix_from_quat(q_r / np.linalg.norm(q_r, axis=1, keepdims=True))
    err_q = np.degrees(orientation_error_rad(q, q_r))
    has_w = "angular_velocity" in s["present"]
    err_w = np.linalg.norm(y[idx, 10:13] - y_ref[idx, 10:13], axis=1) if has_w else None
    dt_rows = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    caption = _sampling_words(t, idx, dt_rows)

    fig = new_figure((9.0, 5.0), dpi=72)
    ax_ref = fig.add_axes((0.0, 0.13, 0.5, 0.74))
    ax_file = fig.add_axes((0.5, 0.13, 0.5, 0.74))
    extent = 1.25 * float(max(np.linalg.norm(half), axis_lengths(half).max()))
    _panel(ax_ref, extent, f"reference ({result.reference_label})")
    _panel(ax_file, extent, f"{Path(result.source).name} (faint dashed: the reference)")
    box_ref = _BoxArtist(ax_ref, half, axes_B, "#8c8c8c")
    ghost = _BoxArtist(ax_file, half, axes_B, "#8c8c8c", ghost=True)
    box = _BoxArtist(ax_file, half, axes_B, "#d62728" if not result.passed else "#1f77b4")
    head = fig.text(0.01, 0.965, "", fontsize=11, va="top", family="monospace")
    fig.text(0.99, 0.965, f"{scenario.name}: {'PASS' if result.passed else 'FAIL'}", fontsize=11, va="top",
             ha="right", color="darkgreen" if result.passed else "darkred")
    foot = fig.text(0.01, 0.015, caption + "\nprincipal axes: e1 (minor) red, e2 (intermediate) green, "
                    "e3 (major) blue; the box has the body's principal moments", fontsize=8, va="bottom")
    last = fig.text(0.5, 0.5, "", fontsize=14, ha="center", va="center", color="darkred", weight="bold",
                    bbox={"fc": "white", "ec": "darkred", "alpha": 0.9})
    del foot

    def draw(k):
        arts = box_ref.update(R_ref[k]) + ghost.update(R_ref[k], 1.0) + box.update(R[k])
        w = f", |Δω| {err_w[k]:.3g} rad/s" if err_w is not None else ""
        head.set_text(f"t = {t[idx[k]]:7.3f} s   orientation error {err_q[k]:6.2f}°{w}")
        if diverged_at is not None and k == len(idx) - 1:
            last.set_text(f"diverged at t = {diverged_at:.4g} s:\nthe animation stops here")
        return [*arts, head, last]

    writer = (animation.PillowWriter(fps=FPS) if writer_name == "pillow"
              else animation.FFMpegWriter(fps=FPS, codec="libvpx-vp9" if str(path).lower().endswith(".webm")
                                          else "h264"))
    anim = animation.FuncAnimation(fig, draw, frames=len(idx), blit=False, repeat=False)
    target = Path(path)
    tmp = target.with_name(f".{target.stem}.partial-{os.getpid()}{target.suffix}")
    try:
        anim.save(tmp, writer=writer, dpi=72)
        os.replace(tmp, target)
    finally:
        tmp.unlink(missing_ok=True)
    return {"frames": len(idx), "caption": caption, "diverged_at_s": diverged_at}


# --- the report's animation: data in the page ----------------------------------------------------------

def _interp_quat(t_src, q_src, t_new) -> np.ndarray:
    """Unit quaternions at ``t_new`` by normalised linear interpolation of sign-continuous ``q_src``."""
    q = sign_continuous(np.asarray(q_src, dtype=float))
    out = np.column_stack([np.interp(t_new, t_src, q[:, i]) for i in range(4)])
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def _pack(a, scale) -> str:
    """float array -> base64 of little-endian int16 (value × scale, rounded): compact page data."""
    v = np.clip(np.round(np.asarray(a, dtype=float) * scale), -32767, 32767)
    v = np.where(np.isfinite(v), v, -32768).astype("<i2")
    return base64.b64encode(v.tobytes()).decode("ascii")


def report_animation(res, sc, styles) -> dict | None:
    """The animation data of scenario ``sc``'s page (None when nothing turns or no body is recorded): the
    box, the frame times (≤ REPORT_FRAMES, uniform in time), and per run (the reference, every variant with
    a saved series) its quaternions at those times (int16 × 32767, base64; a run that diverged stops at
    its divergence), its orientation error (degrees × 100) and its colour; the sampling in words."""
    from reports.canvas import diverged_at
    info = res.scenario(sc)
    ser = res.series(sc)
    ref = ser.get("reference")
    inertia = info.get("inertia_B_kg_m2")
    turns = info.get("varies", {}).get("orientation", True)
    if ref is None or inertia is None or "q_WB" not in ref or not turns:
        return None
    t_ref = np.asarray(ref["t_s"], dtype=float)
    q_ref_all = np.asarray(ref["q_WB"], dtype=float)
    if len(t_ref) < 2 or np.ptp(q_ref_all, axis=0).max() < 1e-6:
        return None
    n = min(REPORT_FRAMES, len(t_ref))
    t = np.linspace(t_ref[0], t_ref[-1], n)
    q_ref = _interp_quat(t_ref, q_ref_all, t)
    moments, axes_B = principal_frame(inertia)
    half = box_half_extents(moments, info.get("mass_kg", 1.0))
    runs = [{"name": "reference", "label": f"reference ({info['reference']})", "color": "#8c8c8c",
             "q": _pack(q_ref, 32767), "err": "", "div": None, "final_err": 0.0}]
    for v in res.variants:
        f = ser.get(v)
        if not f or "q_WB" not in f:
            continue
        tv = np.asarray(f["t_s"], dtype=float)
        ok = np.all(np.isfinite(f["q_WB"]), axis=1)
        tdiv = diverged_at(res, sc, v)
        if tdiv is not None:
            ok &= tv <= tdiv
        if ok.sum() < 2:
            continue
        q = _interp_quat(tv[ok], f["q_WB"][ok], t)
        live = t <= tv[ok][-1] + 1e-12
        q[~live] = np.nan
        err = np.degrees(orientation_error_rad(q, q_ref))
        c = styles[v]["color"]
        runs.append({"name": v, "label": v, "color": "#%02x%02x%02x" % tuple(round(255 * x) for x in c[:3]),
                     "q": _pack(q, 32767), "err": _pack(err, 100), "final_err": float(np.nanmax(err)),
                     "div": None if tdiv is None else (float(tdiv) if math.isfinite(tdiv)
                                                       else float(tv[ok][-1]))})
    variants = [r for r in runs[1:] if r["div"] is None]
    default = max(variants, key=lambda r: r["final_err"])["name"] if variants else None
    every = float(t[1] - t[0]) if n > 1 else 0.0
    span = float(t[-1] - t[0])
    caption = (f"{n} frames, one every {every:.3g} s of the {span:.3g} s run (uniform in time, "
               f"interpolated from the saved series of ≤ 500 samples), {FPS} frames/s.")
    return {"scenario": sc, "t": [round(float(x), 6) for x in t], "fps": FPS,
            "half": [float(x) for x in half], "axes": np.asarray(axes_B, dtype=float).tolist(),
            "camera": list(CAMERA), "runs": runs, "default": default, "caption": caption}
