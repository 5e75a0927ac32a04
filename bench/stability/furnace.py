"""8. Reflectance towards 1: the white furnace at the default tolerance.

Oracle (closed form): a closed cube whose every face emits Le and reflects rho reads
Le / (1 - rho) everywhere inside. Each method is baked once and relit at every rho (its form
factors kept), each solver likewise with the default method.
"""

import numpy as np

from core import relight
from core.settings import BY_NAME, SOLVERS

from . import scenes
from .common import DEFAULT_METHOD, chart, guard, methods, pct, secs, table
from .report import Section

LE = 1.0


def errors(result, rho):
    """Largest relative error of the front patches and of the written corners."""
    exact = LE / (1.0 - rho)
    patch = float(np.abs(result.patch_radiance / exact - 1.0).max())
    corners = result.output.corner_colours if result.output is not None \
        else result.corner_colours
    return patch, float(np.abs(corners / exact - 1.0).max())


def run(ctx):
    tol = BY_NAME["tolerance"].default
    default_solver = BY_NAME["solver"].default
    rhos = ctx.pick([0.5, 0.8, 0.9, 0.95, 0.99, 0.995, 0.999], [0.5, 0.99])
    runs = [(m, default_solver) for m in methods()]
    runs += [(DEFAULT_METHOD, s.value) for s in SOLVERS if s.value != default_solver]
    if ctx.quick:
        runs = [(DEFAULT_METHOD, default_solver), (DEFAULT_METHOD, "jacobi")]
    rows, data = [], {}
    for method, solver in runs:
        scene, _ = scenes.furnace_cube(rhos[0], LE)
        r = ctx.gate.run(scene, ctx.settings(method=method, solver=solver))
        ctx.log(f"furnace {method} {solver}: {r.status} {r.seconds:.1f} s")
        if not r.ok:
            rows.append([f"`{method}`", f"`{solver}`", "all", r.status, "", "", "", "",
                         secs(r.seconds)])
            continue
        base = r.result
        for rho in rhos:
            res = base if rho == rhos[0] else relight(base, reflectance=np.full((1, 3), rho))
            err = errors(res, rho)
            data[method, solver, rho] = err
            rep = res.report
            rows.append([f"`{method}`", f"`{solver}`", f"{rho:g}", rep["solver"],
                         rep["iterations"], "yes" if rep["converged"] else "**no**",
                         pct(err[0]), pct(err[1]),
                         secs(r.seconds) if rho == rhos[0] else "relit"])
    name = "stability_furnace.png"
    x = [1.0 - rho for rho in rhos]
    ticks = (x, [f"{rho:g}" for rho in rhos])
    method_runs = [(m, s) for m, s in runs if s == default_solver]
    solver_runs = [(m, s) for m, s in runs if m == DEFAULT_METHOD]
    panels = [dict(xlabel="rho (axis: 1 - rho, log)", ylabel="worst patch |error| (%)",
                   logx=True, percent=True, xticks=ticks, subtitle=f"solver '{default_solver}'",
                   series=[(m, x, [data.get((m, s, rho), (None,))[0] for rho in rhos])
                           for m, s in method_runs],
                   hlines=[(tol, f"tolerance {tol:g}")]),
              dict(xlabel="rho (axis: 1 - rho, log)", ylabel="worst patch |error| (%)",
                   logx=True, percent=True, xticks=ticks, subtitle=f"method '{DEFAULT_METHOD}'",
                   series=[(s, x, [data.get((m, s, rho), (None,))[0] for rho in rhos])
                           for m, s in solver_runs],
                   hlines=[(tol, f"tolerance {tol:g}")])]
    chart(ctx.images / name, "White furnace: a closed cube, every face emitting and reflecting "
          "rho, against Le / (1 - rho)", panels=panels)
    d = {rho: data[DEFAULT_METHOD, default_solver, rho] for rho in rhos
         if (DEFAULT_METHOD, default_solver, rho) in data}
    worst = max(v[0] for v in d.values())
    worst_c = max(v[1] for v in d.values())
    over = sorted({f"`{m}`/`{s}`" for (m, s, rho), v in data.items() if v[0] > tol})
    sec = Section(
        key="furnace", title="Reflectance towards 1",
        provocation=f"white furnace, rho {min(rhos):g} to {max(rhos):g}",
        worst=f"patches {pct(worst)}, written corners {pct(worst_c)} (tolerance {tol:g} "
              "relative)",
        mitigation="the stopping residual scaled by 1 − max rho (`core/solvers.py` "
                   "`stopping_threshold`); the `tolerance` setting is the result's relative "
                   "accuracy",
        guards=[guard("tests/core/test_stopping.py")])
    sec.blocks += [
        "**Scene.** A closed 2 m cube, one quad per face (inward), every face emitting "
        f"Le = {LE:g} and reflecting rho. Default settings; each method baked once (solver "
        f"'{default_solver}') and each solver once (method '{DEFAULT_METHOD}'), then relit at "
        "every rho with the form factors kept (`core.relight`). **Oracle.** Le / (1 − rho) at "
        "every front patch and every written corner (closed form: the rows of a closed "
        "enclosure sum to 1). **Tolerance**: the `tolerance` setting's default, "
        f"{tol:g} relative (what the README promises at any reflectance); a method whose rows "
        "do not sum to 1 is off by its row-sum error times rho / (1 − rho) whatever the "
        "solver.",
    ]
    sec.chart_link(name, "furnace error against rho per method and per solver")
    sec.blocks.append(table(["method", "solver asked", "rho", "solver used", "iterations",
                             "converged", "worst patch", "worst corner", "time"], rows))
    sec.blocks.append(
        "**What the default does.** "
        f"`{DEFAULT_METHOD}` with solver `'{default_solver}'`: worst patch {pct(worst)}, "
        f"worst written corner {pct(worst_c)} over rho {min(rhos):g}–{max(rhos):g}. "
        + (f"Over the tolerance on patches: {', '.join(over)} (at some rho)." if over else
           "Every run within the tolerance on patches."))
    return sec
