"""Accuracy plots for the report: where in the workspace each servo's error lies."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .sim import golden

__all__ = ["error_map"]


def error_map(robot, plan, path: Path, n_plot: int = 161, n_rest: int = 41) -> dict:
    """Save a PNG with, per servo, |emitted - exact pulse| (pu) over the first two inputs
    (maximum over any further inputs) on a grid of representable inputs. An angle input
    gets one point per degree. Returns the grid size and the plotted maxima per servo."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    specs = list(robot.workspace.inputs)
    counts = [(round(s.max - s.min) + 1 if s.unit == "deg" else n_plot) if k < 2 else n_rest
              for k, s in enumerate(specs)]
    axes = [np.unique(np.round(np.linspace(s.lo, s.hi, n)).astype(np.int64)) for s, n in zip(specs, counts)]
    grids = np.meshgrid(*axes, indexing="ij")
    ints = {s.name: g.ravel() for s, g in zip(specs, grids)}
    real = [ints[s.name] * 2.0 ** -s.frac_bits for s in specs]
    ref = robot.pulses_pu(*real)
    out = golden.outputs(plan, ints)
    shape = grids[0].shape
    fig, axs = plt.subplots(1, len(plan.outputs), figsize=(5 * len(plan.outputs), 4), squeeze=False,
                            constrained_layout=True)
    maxima = {}
    ya, xa = specs[0], specs[1] if len(specs) > 1 else specs[0]
    extent = [axes[-1 if len(specs) == 1 else 1][0] * 2.0 ** -xa.frac_bits,
              axes[-1 if len(specs) == 1 else 1][-1] * 2.0 ** -xa.frac_bits,
              axes[0][0] * 2.0 ** -ya.frac_bits, axes[0][-1] * 2.0 ** -ya.frac_bits]
    rest = " and ".join(s.name for s in specs[2:])
    for ax, o, k in zip(axs[0], plan.outputs, range(len(plan.outputs))):
        err = np.abs(out[o.name] / o.ticks_per_pu - ref[k]).reshape(shape)
        if err.ndim > 2:
            err = err.max(axis=tuple(range(2, err.ndim)))
        elif err.ndim == 1:
            err = err[:, None]
        maxima[o.name] = float(err.max())
        im = ax.imshow(err, origin="lower", aspect="auto", extent=extent, cmap="viridis",
                       vmin=0, vmax=robot.fit.tolerance_pu)
        ax.set_title(f"{o.name}: {'max over ' + rest + ' of ' if rest else ''}|error|, peak {err.max():.3f} pu")
        ax.set_xlabel(f"{xa.name} ({xa.unit})")
        ax.set_ylabel(f"{ya.name} ({ya.unit})")
        fig.colorbar(im, ax=ax, label=f"pu (tolerance {robot.fit.tolerance_pu:g})")
    fig.savefig(path, dpi=80, metadata={"Software": None})
    plt.close(fig)
    return {"file": Path(path).name, "grid": {s.name: len(a) for s, a in zip(specs, axes)}, "max_pu": maxima}
