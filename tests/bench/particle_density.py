#!/usr/bin/python3
r"""How the sample cup's stream depends on the particles per cell, against a finer peer.

The sample cup (sample_scenes/capture_cup.json) drains at --viscosity and is simulated with the built
engine at --resolution with 8 and with 27 particles per cell, and at --peer-resolution with 8 (the
Table 1 references' grid and seeding). In horizontal slabs of the stream below the cup, at the
frames --at, it prints the liquid the particles carry (their count × their volume, as an area in
mm²) and the area inside the surface the engine wrote (frame_NNNNN.vdb, "surface" < 0), each with
its ratio to the peer's. A stream that a coarse grid carries and draws as the fine one does gives
ratios of 1; the silhouettes an identification compares follow the surface.

Needs Debian's python3-openvdb for the surfaces.

    /usr/bin/python3 tests/bench/particle_density.py
    /usr/bin/python3 tests/bench/particle_density.py --viscosity 3 --frames 20 --at 10,20
"""
import argparse
import json
import pathlib
import statistics
import tempfile

import numpy as np
import pyopenvdb

from viscosity_floor import read_particles, scene_variant, simulate  # beside this script

ROOT = pathlib.Path(__file__).resolve().parents[2]
SLAB_CENTRES = [0.03, 0.045, 0.06, 0.075, 0.09]  # m above the ground; the cup's bottom is at 0.10
SLAB_HALF_HEIGHT = 0.0075  # m
STREAM_RADIUS = 0.02  # m from the cup's axis


def particle_areas(particles_file, particle_volume):
    """The liquid in each slab as the area (mm²) of a stream of the slab's height holding it."""
    positions = read_particles(particles_file)[:, :3].astype(float)
    near = np.hypot(positions[:, 0], positions[:, 1]) < STREAM_RADIUS
    return [1e6 * particle_volume * np.count_nonzero(near & (np.abs(positions[:, 2] - z) < SLAB_HALF_HEIGHT))
            / (2 * SLAB_HALF_HEIGHT) for z in SLAB_CENTRES]


def surface_areas(vdb_file):
    """The mean area (mm²) inside the surface over each slab's voxel layers."""
    grid = pyopenvdb.read(str(vdb_file), "surface")
    voxel = grid.transform.voxelSize()[0]
    low, high = grid.evalActiveVoxelBoundingBox()
    values = np.full([h - l + 1 for l, h in zip(low, high)], grid.background, dtype=np.float32)
    grid.copyToArray(values, ijk=low)  # inactive voxels inside hold −background
    origin = np.array(grid.transform.indexToWorld(tuple(int(i) for i in low)))
    x = origin[0] + voxel * np.arange(values.shape[0])
    y = origin[1] + voxel * np.arange(values.shape[1])
    z = origin[2] + voxel * np.arange(values.shape[2])
    near = np.hypot(x[:, None], y[None, :]) < STREAM_RADIUS
    inside = (values < 0) & near[:, :, None]
    layers = [np.abs(z - centre) < SLAB_HALF_HEIGHT for centre in SLAB_CENTRES]
    return [1e6 * voxel * voxel * inside[:, :, layer].sum(axis=(0, 1)).mean() if layer.any() else 0.0
            for layer in layers]


def ratios(values, references):
    """values / references where the reference holds liquid."""
    return [v / r for v, r in zip(values, references) if r > 0]


def median_text(values):
    return f"{statistics.median(values):.3f}" if values else "n/a (no liquid)"


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--engine", default=ROOT / "build/bin/viscoscope", type=pathlib.Path)
    parser.add_argument("--scene", default=ROOT / "sample_scenes/capture_cup.json", type=pathlib.Path)
    parser.add_argument("--resolution", type=int, default=48)
    parser.add_argument("--peer-resolution", type=int, default=96)
    parser.add_argument("--viscosity", type=float, default=1.0)
    parser.add_argument("--frames", type=int, default=30)
    parser.add_argument("--at", default="10,15,20,25,30", help="frames compared")
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--peer-seed", type=int, default=11)
    args = parser.parse_args()
    frames = [int(f) for f in args.at.split(",")]
    if not frames or min(frames) < 1 or max(frames) > args.frames:
        parser.error(f"--at: frames must lie in 1..{args.frames}")

    base = json.loads(args.scene.read_text(encoding="utf-8"))
    runs = [(args.peer_resolution, 8, args.peer_seed), (args.resolution, 8, args.seed), (args.resolution, 27, args.seed)]
    print(f"sample cup at η {args.viscosity:g} Pa·s; stream slabs at z = "
          f"{', '.join(f'{1000 * z:.0f}' for z in SLAB_CENTRES)} mm (±{1000 * SLAB_HALF_HEIGHT:.1f}), frames {args.at}",
          flush=True)
    measured = {}
    with tempfile.TemporaryDirectory(prefix="particle_density_") as tmp:
        for resolution, per_cell, seed in runs:
            scene, cell = scene_variant(base, resolution, args.viscosity, args.frames, seed, per_cell, vdb=True)
            out = simulate(args.engine, scene, pathlib.Path(tmp) / f"{resolution}_{per_cell}",
                           f"{resolution} cells, {per_cell} particles per cell")
            measured[resolution, per_cell] = {
                f: (particle_areas(out / f"particles_{f:05d}.bin", cell ** 3 / per_cell),
                    surface_areas(out / f"frame_{f:05d}.vdb")) for f in frames}
    peer = measured[runs[0][:2]]
    for key, by_frame in measured.items():
        carried, drawn, own = [], [], []
        print(f"{key[0]:4d} cells, {key[1]:2d} per cell:")
        for f, (particles, surface) in by_frame.items():
            peer_particles, peer_surface = peer[f]
            carried += ratios(particles, peer_particles)
            drawn += ratios(surface, peer_surface)
            own += ratios(surface, particles)
            print(f"  frame {f:3d}  particles " + " ".join(f"{a:6.1f}" for a in particles) +
                  "  surface " + " ".join(f"{a:6.1f}" for a in surface) + "  mm²")
        print(f"  medians: particles / peer's {median_text(carried)}, surface / peer's {median_text(drawn)}, "
              f"surface / own particles {median_text(own)}")


if __name__ == "__main__":
    main()
