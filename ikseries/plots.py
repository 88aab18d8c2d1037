"""Accuracy plots for the report: where in the workspace each servo's error lies."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .sim import golden

__all__ = ["error_map"]


def error_map(robot, plan, path: Path, n_theta: int = 361, n_r: int = 41, n_z: int = 41) -> dict:
    """Save a PNG with, per servo, max over Z of |emitted - exact pulse| (pu) on an (R, theta)
    grid of representable inputs. Returns the grid size and the plotted maxima per servo."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    specs = {i.name: i for i in robot.inputs}
    r_in, th_in, z_in = (specs[n] for n in robot.geometry.inputs)
    axes = [np.unique(np.round(np.linspace(s.lo, s.hi, n)).astype(np.int64))
            for s, n in ((r_in, n_r), (th_in, n_theta), (z_in, n_z))]
    rr, tt, zz = np.meshgrid(*axes, indexing="ij")
    ints = {r_in.name: rr.ravel(), th_in.name: tt.ravel(), z_in.name: zz.ravel()}
    real = [ints[s.name] * 2.0 ** -s.frac_bits for s in (r_in, th_in, z_in)]
    ref = robot.pulses_pu(*real)
    out = golden.outputs(plan, ints)
    shape = rr.shape
    fig, axs = plt.subplots(1, len(plan.outputs), figsize=(5 * len(plan.outputs), 4), squeeze=False,
                            constrained_layout=True)
    maxima = {}
    extent = [axes[1][0] * 2.0 ** -th_in.frac_bits, axes[1][-1] * 2.0 ** -th_in.frac_bits,
              axes[0][0] * 2.0 ** -r_in.frac_bits, axes[0][-1] * 2.0 ** -r_in.frac_bits]
    for ax, o, k in zip(axs[0], plan.outputs, range(len(plan.outputs))):
        err = np.abs(out[o.name] / o.ticks_per_pu - ref[k]).reshape(shape).max(axis=2)
        maxima[o.name] = float(err.max())
        im = ax.imshow(err, origin="lower", aspect="auto", extent=extent, cmap="viridis",
                       vmin=0, vmax=robot.tolerance_pu)
        ax.set_title(f"{o.name}: max over {z_in.name} of |error|, peak {err.max():.3f} pu")
        ax.set_xlabel(f"{th_in.name} ({th_in.unit})")
        ax.set_ylabel(f"{r_in.name} ({r_in.unit})")
        fig.colorbar(im, ax=ax, label=f"pu (tolerance {robot.tolerance_pu:g})")
    fig.savefig(path, dpi=80, metadata={"Software": None})
    plt.close(fig)
    return {"file": Path(path).name, "grid": {n: len(a) for n, a in zip((r_in.name, th_in.name, z_in.name), axes)},
            "max_pu": maxima}
