"""The chart of :mod:`bench.compare.coarse`: error against output vertices and against time."""

from .coarse import WORST, on_module

#: Series of the chart: uniform grids on and off the design module (:func:`on_module`) apart.
STYLE = {"adaptive": ("s", "C0"), "uniform": ("o-", "C1"), "uniform off": ("d--", "C4"),
         "cycles": ("^-", "C2")}


def chart(rows, path, title):
    """Two log-log panels: error against output vertices, error against wall time."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.8))
    ref = next(r for r in rows if r["method"] == "reference")
    for ax, key, xlabel in ((axes[0], "vertices", "output vertices"),
                            (axes[1], "t_total", "wall time (s, 2 shared cores)")):
        for series, (style, colour) in STYLE.items():
            method = series.split()[0]
            rs = sorted((r for r in rows if r["method"] == method
                         and (method != "uniform" or on_module(r["scene"], r["grid"])
                              == (series == "uniform"))), key=lambda r: r[key])
            if not rs:
                continue
            name = {"adaptive": "adaptive mesh (coarse model)",
                    "uniform": "ours, uniform grid on the design module",
                    "uniform off": "ours, uniform grid off the module",
                    "cycles": "Cycles, pre-meshed copy"}[series]
            ax.plot([r[key] for r in rs], [100 * r["rms"] for r in rs], style, color=colour,
                    label=name, ms=6)
            ax.plot([r[key] for r in rs], [100 * r["rms_rest"] for r in rs], style[0],
                    color=colour, mfc="none", ms=6, alpha=0.6)
            for j, r in enumerate(rs):
                tag = {"adaptive": r["label"].replace("adaptive ", ""),
                       "uniform": "%g m" % r.get("grid", 0),
                       "cycles": "%d spp" % int(r.get("samples", 0))}[method]
                # Adaptive runs often land on one spot: their labels are stacked.
                dy = 3 - 8 * (j % 4) if method == "adaptive" else 3
                ax.annotate(tag, (r[key], 100 * r["rms"]), fontsize=6, xytext=(5, dy),
                            textcoords="offset points")
            d = [r for r in rs if r["label"] == "adaptive (defaults)"]
            if d:
                ax.plot([d[0][key]], [100 * d[0]["rms"]], "*", color="C3", ms=14,
                        label="adaptive at defaults")
        ax.plot([], [], "o", color="grey", mfc="none",
                label="open: without each run's %d worst faces" % WORST)
        ax.axhline(100 * ref["rms"], color="grey", ls=":", label="reference noise")
        for level in (5, 2):
            ax.axhline(level, color="r", lw=0.6, ls="-.")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        lo, hi = ax.get_xlim()
        if hi < 10 * lo:        # no power of ten in range (the apartment's few runs)
            ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(4))
            ax.xaxis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
        ax.set_xlabel(xlabel)
        ax.set_ylabel("area-weighted relative RMS error (%)")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=7, loc="lower left")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
