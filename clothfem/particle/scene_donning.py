"""Donning as the first stage of a scene (``[initial] don = true``, docs/donning.md).

The scene's body must be the seven segments of :func:`clothfem.body.lower_body` played from
one C3D file, and its garment the generated pants (``mesh.generator = "pants"``). Before the
shell model is built, the particle model dons the pants onto the body's pose at the start
of the scene's window (:func:`clothfem.particle.donning.don_pants`, parameters from the
scene's ``[donning]`` table); the shell then starts from the donned positions, its
stress-free reference staying the pants pattern, as with ``initial.positions``.

The pants dimensions are the donning fit's (:func:`clothfem.particle.donning.fit_pants`): a
``[mesh]`` dimension the scene leaves out is taken from the fit, one it gives must equal the
fit's (the donned nodes are matched to the mesh by their pattern positions).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from mpi4py import MPI

from ..spec import Scene
from .donning import Growth, PantsDonning, PantsFit, Relaxation, don_pants, fit_pants

__all__ = ["DIMENSIONS", "don_scene", "fit_dimensions", "check_scene"]

#: The ``[mesh]`` keys of the pants generator that the donning fit sets.
DIMENSIONS = ("waist_radius", "hip_radius", "leg_radius", "leg_length", "crotch_depth")
DIMENSIONS += ("leg_spacing",)


def _recording(scene: Scene) -> tuple[str, float]:
    """The C3D file and window start [s] of the scene's lower body (ValueError naming the
    key if the body is not one recording's seven segments)."""
    from ..body.lower_body import LOWER_BODY_SEGMENTS

    segs = {seg.name: seg for seg in scene.body}
    missing = [n for n in LOWER_BODY_SEGMENTS if n not in segs]
    if missing:
        raise ValueError(
            f"body: initial.don needs the segments {', '.join(LOWER_BODY_SEGMENTS)} of "
            f"clothfem.body.lower_body, missing {', '.join(missing)}"
        )
    first = segs[LOWER_BODY_SEGMENTS[0]]
    for i, seg in enumerate(scene.body):
        if seg.name not in LOWER_BODY_SEGMENTS:
            continue
        if seg.type != "mocap" or seg.file != first.file:
            raise ValueError(f"body[{i}].file: initial.don needs every segment from one C3D file")
        if seg.window != first.window:
            raise ValueError(f"body[{i}].window: initial.don needs one window for every segment")
    if Path(first.file).suffix.lower() != ".c3d":
        raise ValueError(f"body[0].file: initial.don needs a C3D file, got {first.file!r}")
    window = first.window
    return first.file, float(window[0]) if window is not None else 0.0


def _fit(scene: Scene) -> PantsFit:
    d, m = scene.donning, scene.mesh
    return PantsFit(
        ease=d.ease, waist_height=d.waist_height, n_around=m.n_around, n_along=m.n_along
    )


def _relaxation(scene: Scene) -> Relaxation:
    d = scene.donning
    return Relaxation(
        growth=Growth(start=d.start_scale, time=d.grow_time),
        settle_time=d.settle_time,
        alpha=d.alpha,
        max_stretch=d.max_stretch,
        mu=d.mu,
        self_distance=d.self_distance if d.self_distance > 0 else None,
    )


def _body_and_frame(scene: Scene):
    """The :class:`LowerBody` of the scene's recording and the row at its window start."""
    from ..body.lower_body import lower_body_from_c3d

    path, start = _recording(scene)
    body = lower_body_from_c3d(path)
    times = body.motions[body.names[0]].times
    frame = int(np.searchsorted(times, start - 1e-9))
    return body, frame


def fit_dimensions(scene: Scene) -> dict[str, float]:
    """The pants dimensions [m] of the donning fit of a scene with ``initial.don``."""
    body, frame = _body_and_frame(scene)
    geometry = fit_pants(body=body, frame=frame, fit=_fit(scene)).geometry
    return {k: float(geometry[k]) for k in DIMENSIONS}


def check_scene(scene: Scene) -> dict[str, float]:
    """Validation of ``initial.don`` (ValueError ``"<key>: <message>"``); returns the pants
    dimensions [m] the scene leaves out, the fit's."""
    m = scene.mesh
    if m.generator != "pants":
        raise ValueError(
            f"mesh.generator: initial.don dons the generated pants, got {m.generator!r}"
        )
    if scene.initial.positions is not None:
        raise ValueError("initial.positions: give either positions or don = true, not both")
    body, frame = _body_and_frame(scene)
    for i, seg in enumerate(scene.body):
        if seg.name in body.radii:
            r = np.asarray(body.radii[seg.name])
            if np.abs(np.asarray(seg.radii) - r).max() > 5e-4:
                raise ValueError(
                    f"body[{i}].radii: the donning dons onto {seg.name} with the radii "
                    f"{np.round(r, 4).tolist()} m of clothfem.body.lower_body (within 0.5 mm)"
                )
    fitted = fit_pants(body=body, frame=frame, fit=_fit(scene)).geometry
    left_out = {}
    for k in DIMENSIONS:
        want, given = float(fitted[k]), getattr(m, k)
        if given is None:
            left_out[k] = want
        elif abs(given - want) > 1e-9 * max(1.0, abs(want)):
            raise ValueError(
                f"mesh.{k}: {given!r} is not the donning fit's {want!r} [m] (leave it out to "
                "take the fit's)"
            )
    return left_out


def don_scene(scene: Scene, *, comm: MPI.Comm, progress=None) -> PantsDonning | None:
    """Don the scene's pants on rank 0 (None on the other ranks); ``progress``: a
    :class:`clothfem.io.Progress` to report to."""
    if comm.rank != 0:
        return None
    relax = _relaxation(scene)

    def on_row(row: tuple) -> None:
        t, scale, gap, active, strain = row
        progress.update(
            t / relax.t_end,
            f"donning t {t:.3f} s  radius x {scale:.2f}  min gap {1e3 * gap:.2f} mm  "
            f"contact {active}  max strain {strain:.3f}",
        )

    body, frame = _body_and_frame(scene)
    return don_pants(
        body=body,
        frame=frame,
        fit=_fit(scene),
        relax=relax,
        on_row=on_row if progress is not None else None,
    )
