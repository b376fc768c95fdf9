"""What `sasmi calibrate` writes: RUN/preset.toml, RUN/report.md and its figures, and what the chips pin
(RUN/sensitivity.json, knob by knob; RUN/together.json, pairs of knobs).

The report compares the start and the calibrated preset on renders of scenes no trial rendered
(seed + 1), each statistic against the real chips' median with its `sasmi stats --check` tolerance,
and the φ-FID ratio as `sasmi evaluate` measures it.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from sasmi.chips.compare import TOLERANCES
from sasmi.chips.stats import STATISTICS
from sasmi.images import write_text
from sasmi.realism.calibration_pins import PARTNER, RISE, SPAN, STEP, best_tenth, pairs
from sasmi.realism.calibration_study import lowest, searched_seconds
from sasmi.realism.preset_space import knob, start_values

SHOWN = 6  # chips per column of the sheet
PARTNERS = 3  # knobs named in a row's *moves with*
VERDICTS = {True: "yes", False: "**no**", None: "cannot tell"}  # what the chips pin, as the tables say it


def _number(v: float) -> str:
    return "—" if not math.isfinite(v) else f"{v:.3g}"


def _side(found) -> str:
    if found is None:
        return "none tried"
    if found == "range":
        return "range ends"
    profiled = " (profile)" if found.get("profiled") else ""
    moved = ", ".join(f"{n} {_number(v)}" for n, v in found.get("moved_too", []))
    return (f"{_number(found['value'])}{profiled}: {found['rise']:+.0%} ± {found['error']:.0%}"
            + (f" (with {moved})" if moved else ""))


def sensitivity_lines(pins: dict[str, dict], best: dict[str, float], profile_budget: int = 0) -> list[str]:
    loose = [n for n, p in pins.items() if not p["alone"]]
    traded = [n for n, p in pins.items() if p["alone"] and p["pinned"] is False]
    untold = [n for n, p in pins.items() if p["pinned"] is None]
    fresh = next(iter(pins.values()))["fresh"] if pins else [0.0]
    lines = [f"**What the chips pin.** Each knob moved alone by {STEP:.0%} of its search range, down and up, from "
             f"the calibrated preset (the search's scenes): the chips pin it alone when the objective rises by "
             f"{RISE:.0%} or more. " + (f"These they cannot pin, any value scoring alike: {', '.join(loose)}. "
                                        if loose else "They pin every knob alone. ")
             + f"A search fits its own scenes' draws: on {len(fresh)} other draws the calibrated preset scores "
               f"{np.mean(fresh):.3g} ± {np.std(fresh):.2g}. For each knob that moves it alone, the trials that "
               f"scored best with that knob more than {SPAN:.0%} below and above its calibrated value were scored "
               f"on the same draws (*beyond*: the knob's value there and the objective's rise ± its standard "
               f"error over the draws), and the knob is pinned when both score {RISE:.0%} or more worse (and worse "
               f"by more than twice that error), not pinned when one scores less than {RISE:.0%} worse by more than "
               f"twice its error. "
             + (f"The search may not have followed a ridge (altitude with range, gain with albedo) that far, so "
                f"each side those trials left pinned or undecided was also profiled: the knob held {SPAN:.0%} away "
                f"and the other knobs searched again ({profile_budget} settings a side, CMA-ES from the line the "
                f"best trials lie along), the lower of the two rises counting (*(profile)*). A yes speaks for "
                f"the settings tried. " if profile_budget else
                "A yes speaks for the trials the search tried: a knob on a ridge it did not follow far (altitude "
                "with range and chip size) can still trade. ")
             + (f"These move it alone, but a value more than {SPAN:.0%} away scores as well (they trade against "
                f"other knobs, or the spread over scene draws hides them): {', '.join(traded)}. " if traded else "")
             + (f"These the draws cannot tell, or nothing was tried that far on a side: "
                f"{', '.join(untold)}. " if untold else "")
             + f"*Moves with*: the knobs moving the objective alone that rise (+) or fall (−) with this one among "
               f"the best tenth of the trials (correlation {PARTNER:g} or more either way, the strongest {PARTNERS}): "
               f"along such a line the objective is flat, so the chips see at most the pair together.",
             "",
             f"| knob | calibrated | moved to | objective rise | beyond −{SPAN:.0%} | beyond +{SPAN:.0%} | pinned "
             f"| moves with |",
             "|---|---|---|---|---|---|---|---|"]
    for n, p in pins.items():
        sides = p.get("beyond", {})
        below, above = (_side(sides[s]) if s in sides else "—" for s in ("below", "above"))
        partners = ", ".join(f"{m} ({r:+.2f})" for m, r in p.get("moves_with", [])[:PARTNERS]) or "—"
        lines.append(f"| {n} | {_number(best[n])} | {_number(p['moved'][0])}, {_number(p['moved'][1])} | "
                     f"{p['share']:+.0%} | {below} | {above} | {VERDICTS[p['pinned']]} | {partners} |")
    return lines


def together_lines(together: dict[str, dict], profile_budget: int = 0) -> list[str]:
    if not together:
        return []
    lines = [f"**What the chips pin together.** Each pair of knobs above that moves together, judged as a knob is: "
             f"its ratio (a : b, where they rise together) or product (a × b, where one falls as the other rises) "
             f"held {SPAN:.0%} below and above its calibrated value by the best trials there"
             + (f" and a profile (the first knob set to hold it, the others searched again, {profile_budget} "
                f"settings a side)" if profile_budget else "")
             + ", scored on the same other draws. A yes where neither knob alone is pinned: the chips pin what the "
               "pair makes together (a grazing angle, a brightness, a size in pixels), not each knob.", "",
             f"| knobs together | calibrated | beyond −{SPAN:.0%} | beyond +{SPAN:.0%} | pinned |",
             "|---|---|---|---|---|"]
    for label, t in together.items():
        below, above = (_side(t["beyond"][s]) for s in ("below", "above"))
        lines.append(f"| {label} | {_number(t['calibrated'])} | {below} | {above} | {VERDICTS[t['pinned']]} |")
    return lines


def refinement_lines(refinement: dict | None) -> list[str]:
    if not refinement:
        return []
    scales = ", ".join(f"{p} x {s:.3g}" for p, s in refinement["scales"].items())
    after = "invalid: " + refinement["invalid"] if refinement.get("invalid") else f"{refinement['after']:.3g}"
    return [f"Gradient refinement, {refinement['steps']} steps of `sasmi fit-scene` from the calibrated preset: "
            f"{scales}; objective on these renders {refinement['before']:.3g} -> {after}: "
            f"{'kept (the calibrated column above)' if refinement['kept'] else 'not kept'}.", ""]


def preset_text(record: dict, cfg, start, raw: dict, values: dict[str, float], refinement: dict | None = None,
                search: str = "") -> str:
    from sasmi.realism.fit_scene import preset_toml

    before = start_values(start.raw, cfg.params)
    header = [f"# Calibrated by `sasmi calibrate`{search} from {Path(record['start']).name} to the chips of "
              f"{record['real']}", f"# ({len(cfg.params)} knobs; docs/calibrate.md). Start -> calibrated:"]
    header += [f"#   {n}: {before[n]:.4g} -> {values[n]:.4g}" for n in cfg.params]
    if refinement and refinement["kept"]:
        header += ["# then refined by gradients (sasmi fit-scene): "
                   + ", ".join(f"{p} x {s:.3g}" for p, s in refinement["scales"].items())]
    return "\n".join(header) + "\n" + preset_toml(raw)


def statistics_table(real, shown: dict) -> list[str]:
    lines = ["| statistic | real | start | calibrated | tolerance |", "|---|---|---|---|---|"]
    for key in real.checked:
        tol = real.tolerances[key]
        label = STATISTICS[key][0] if key in STATISTICS else "targets found (share of chips)"
        cells = [label + ("" if key in TOLERANCES else " (calibrate only)"), _number(real.medians[key])]
        for name in ("start", "calibrated"):
            s = shown[name][1]
            cells.append(f"{_number(s['medians'][key])} {'ok' if s['distances'][key] <= 1 else '**FAIL**'}")
        lines.append("| " + " | ".join(cells + [tol.describe()]) + " |")
    checked = sum(k in TOLERANCES for k in real.checked)
    passed = [f"{shown[n][1]['passed']} of {checked}" for n in ("start", "calibrated")]
    lines.append(f"| **within `sasmi stats --check` tolerance** | | {passed[0]} | {passed[1]} | |")
    return lines


def distribution_table(real, shown: dict) -> list[str]:
    """Each statistic of the distribution term: the real chips' median and the ROC AUC by which it alone tells the
    start's and the calibrated preset's renders from them."""
    from sasmi.eval.signature import STATISTICS as SIGNATURE
    from sasmi.realism.calibration_objective import auc_tolerance

    tolerance = auc_tolerance(len(real.phi), len(shown["start"][0]))
    lines = [f"How well each statistic alone tells the renders from the real chips, chip by chip (ROC AUC over the "
             f"chips that show it; 0.5 not at all, under 0.5 the renders' values run lower; two samples of one "
             f"distribution lie within about ± {tolerance:.2f} of 0.5 at these numbers of chips; the last nine are "
             "`sasmi evaluate`'s signature):", "",
             "| statistic | real median | start | calibrated |", "|---|---|---|---|"]
    for name, values in real.per_chip.items():
        label = STATISTICS[name][0] if name in STATISTICS else f"{name} ({SIGNATURE[name]})"
        aucs = [shown[n][1]["aucs"].get(name) for n in ("start", "calibrated")]
        cells = ["—" if a is None else f"{a:.2f}" + ("" if abs(a - 0.5) <= tolerance else " **far**") for a in aucs]
        median = float(np.nanmedian(values)) if np.isfinite(values).any() else math.nan
        lines.append(f"| {label} | {_number(median)} | {' | '.join(cells)} |")
    return lines


def objective_figure(studies: list, chosen: int, path: Path) -> None:
    """The objective over the search: every trial, and each search's best so far; the statistics the chosen
    search's best trial so far passes."""
    from matplotlib.figure import Figure

    from sasmi.eval.report import save_figure

    t0 = min(s.trials[0].datetime_start for s in studies if s.trials and s.trials[0].datetime_start)
    fig = Figure(figsize=(9, 3.5))
    ax, ax_pass = fig.subplots(1, 2)
    for search, study in enumerate(studies):
        done = [t for t in study.trials if t.value is not None and t.datetime_complete is not None]
        if not done:
            continue
        minutes = np.array([(t.datetime_complete - t0).total_seconds() / 60 for t in done])
        values = np.array([t.value for t in done])
        ax.scatter(minutes, values, s=6, color="0.6", label="trial" if search == 0 else None)
        name = "best so far" if len(studies) == 1 else f"search {search}" + (", kept" if search == chosen else "")
        ax.plot(minutes, np.minimum.accumulate(values), color=f"C{search}", label=name)
        if search == chosen:
            chosen_minutes, passes, best = minutes, [], 0
            for i, value in enumerate(values):  # the statistics passed by the best trial so far
                best = i if value < values[best] else best
                passes.append(done[best].user_attrs.get("passed", 0))
    ax.set(xlabel="minutes since the first trial", ylabel="objective", yscale="log", title="objective")
    ax.legend()
    ax_pass.step(chosen_minutes, passes, where="post")
    ax_pass.set(xlabel="minutes since the first trial", ylabel="statistics",
                title="best trial: statistics within tolerance", ylim=(0, len(TOLERANCES) + 0.5))
    fig.tight_layout()
    save_figure(fig, path)


def ridges_figure(pins: dict[str, dict], trials: list[tuple[float, dict]], best: dict[str, float],
                  path: Path, together: dict[str, dict] | None = None) -> bool:
    """Each pair of knobs that move together: every trial, the best tenth and the calibrated preset, on the
    search scales; where the pair was judged (`together`), the line holding its ratio or product and the lines
    SPAN either side, with its verdict. False (and no file) where no pair moves together."""
    from matplotlib.figure import Figure
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    from sasmi.eval.report import save_figure

    drawn = pairs(pins)
    if not drawn:
        return False
    top = best_tenth(list({n for a, b, _ in drawn for n in (a, b)}), trials)
    fig = Figure(figsize=(3.8 * min(len(drawn), 3), 3.2 * math.ceil(len(drawn) / 3)))
    axes = np.atleast_1d(fig.subplots(math.ceil(len(drawn) / 3), min(len(drawn), 3))).ravel()
    for ax, (a, b, r) in zip(axes, drawn):
        ax.set(xscale="log" if knob(a).log else "linear", yscale="log" if knob(b).log else "linear")
        for shown, style in ((trials, dict(s=4, color="0.75", label="trial")),
                             (top, dict(s=8, color="C0", label="best tenth"))):
            points = np.array([(knobs[a], knobs[b]) for _, knobs in shown if a in knobs and b in knobs])
            if len(points):
                ax.scatter(points[:, 0], points[:, 1], **style)
        ax.scatter([best[a]], [best[b]], marker="*", s=120, color="C3", label="calibrated")
        judged = next((t for t in (together or {}).values() if t["knobs"] == [a, b]), None)
        title = f"r {r:+.2f}"
        if judged is not None:  # b = (c / a)^(1 / power): the pair's combination c held, and SPAN either side
            (x0, x1), ylim = ax.get_xlim(), ax.get_ylim()
            x = np.geomspace(x0, x1) if knob(a).log else np.linspace(max(x0, 1e-9 * x1), x1)
            for share, style in ((1.0, "-"), (1 - SPAN, ":"), (1 + SPAN, ":")):
                ax.plot(x, (judged["calibrated"] * share / x) ** (1 / judged["power"]), style, color="C3", lw=1)
            ax.set(xlim=(x0, x1), ylim=ylim)
            title += f"; pinned together: {VERDICTS[judged['pinned']].strip('*')}"
        ax.set(xlabel=a, ylabel=b, title=title)
        for axis, name in ((ax.xaxis, a), (ax.yaxis, b)):
            if knob(name).log:  # a knob's range spans a decade or two: 1-2-5 ticks, plainly written
                axis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
                axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
                axis.set_minor_formatter(NullFormatter())
    axes[0].legend(fontsize=7)
    for ax in axes[len(drawn):]:
        ax.axis("off")
    fig.tight_layout()
    save_figure(fig, path)
    return True


def sheet_figure(real, shown: dict, path: Path) -> None:
    from matplotlib.figure import Figure

    from sasmi.eval.report import save_figure

    columns = [("real", real.images), ("start", shown["start"][0]), ("calibrated", shown["calibrated"][0])]
    fig = Figure(figsize=(6, 2 * SHOWN))
    axes = fig.subplots(SHOWN, 3)
    rng = np.random.default_rng(0)
    for col, (name, images) in enumerate(columns):
        picks = rng.choice(len(images), min(SHOWN, len(images)), replace=False)
        for row in range(SHOWN):
            ax = axes[row, col]
            ax.axis("off")
            if row < len(picks):
                ax.imshow(images[picks[row]], cmap="gray", vmin=0, vmax=1)
            if row == 0:
                ax.set_title(name)
    fig.tight_layout()
    save_figure(fig, path)


def search_lines(studies: list, chosen: int, judgement: list[tuple[int, dict]]) -> list[str]:
    """The searches side by side: trials, best and calibrated trial, its report renders judged, which was kept."""
    if len(studies) == 1:
        return []
    # a calibrated trial's objective on other draws of its search's scenes: how much of its score was its own draw's
    elsewhere = [next(c[2] for c in s.user_attrs["contenders"]["scores"] if c[0] == number)
                 for s, (number, _) in zip(studies, judgement)]
    rows = [f"| {i}{' (kept)' if i == chosen else ''} | {len(s.trials)} | {searched_seconds([s]) / 60:.1f} | "
            f"{lowest(s):.3g} | {number} | {elsewhere[i]:.3g} | {score['two_sample']:.3f} ± "
            f"{score['two_sample_std']:.3f} | {score['phi_ratio']:.2f} | {score['passed']} |"
            for i, (s, (number, score)) in enumerate(zip(studies, judgement))]
    kept = judgement[chosen][1]
    close = [str(i) for i, (_, s) in enumerate(judgement) if i != chosen and s["two_sample"] - kept["two_sample"]
             < max(s["two_sample_std"], kept["two_sample_std"])]
    who = f"Search {close[0]} was" if len(close) == 1 else f"Searches {', '.join(close)} were"
    near = [f"{who} told apart within the test's spread over folds of search {chosen}'s: a close choice, which "
            "held-out chips may reverse.", ""] if close else []
    others = ", ".join(f"`search-{i}.toml`" for i in range(len(studies)) if i != chosen)
    return [f"{len(studies)} searches from the start, each its own sampler path over its own draw of the scenes, "
            f"shared the search time. Each one's calibrated trial rendered the report's scenes, and the one a small "
            f"CNN (the two-sample test of `sasmi evaluate`, ROC AUC) told least from the real chips is kept: search "
            f"{chosen}. Of calibrated presets, the one that test tells less often from the chips calibrated to was "
            f"told less often from held-out chips too (docs/calibrate.md). What follows is search {chosen}'s; the "
            f"others' calibrated presets are {others}, to render against held-out chips of your own.", "",
            "| search | trials | minutes | best objective | calibrated trial | on other draws | two-sample | "
            "φ-FID ratio | statistics within tolerance |", "|---|---|---|---|---|---|---|---|---|", *rows, "", *near]


def write_report(out: Path, record: dict, cfg, start, raws: list[dict], real, studies: list, chosen: int,
                 judgement: list[tuple[int, dict]], shown: dict, pins: dict[str, dict], together: dict[str, dict],
                 refinement: dict | None = None) -> None:
    """`raws`: each search's calibrated preset, the kept one (`chosen`) refined where `refinement` was kept."""
    import json

    study = studies[chosen]
    best = study.trials[study.user_attrs["calibrated_trial"]]
    draws, contenders = study.user_attrs["contenders"]["draws"], study.user_attrs["contenders"]["scores"]
    write_text(out / "sensitivity.json", json.dumps(pins, indent=2) + "\n")
    write_text(out / "together.json", json.dumps(together, indent=2, ensure_ascii=False) + "\n")
    # the kept preset, and each other search's beside it: where the choice was close, held-out chips may prefer one
    for i, (raw, (number, _)) in enumerate(zip(raws, judgement)):
        kept = i == chosen
        write_text(out / ("preset.toml" if kept else f"search-{i}.toml"),
                   preset_text(record, cfg, start, raw, studies[i].trials[number].params, refinement if kept else None,
                               "" if kept else f" (search {i}, not kept: report.md)"))
    objective_figure(studies, chosen, out / "objective.png")
    sheet_figure(real, shown, out / "sheet.png")
    trials = [(t.value, t.params) for t in study.trials if t.value is not None]
    ridges = ridges_figure(pins, trials, best.params, out / "ridges.png", together)
    if not ridges:  # a rerun's report: no figure of pairs this run does not find
        (out / "ridges.png").unlink(missing_ok=True)
    ratio = {n: f"{s['phi_ratio']:.2f} ± {s['phi_ratio_std']:.2f}" for n, (_, s) in shown.items()}
    pr = {n: f"{s['precision']:.2f} / {s['recall']:.2f}" for n, (_, s) in shown.items()}
    told = {n: f"{s['two_sample']:.2f} ± {s['two_sample_std']:.2f}" for n, (_, s) in shown.items()}
    lines = [
        f"# Calibration of {Path(record['start']).name} to {record['real']}", "",
        *search_lines(studies, chosen, judgement),
        f"{len(study.trials)} trials in {searched_seconds([study]) / 60:.1f} minutes of search ({cfg.sampler}, "
        f"{cfg.chips} renders of {cfg.size}² px per trial"
        f"{', each generation on its own draw of the scenes' if cfg.redraw_scenes else ''}); "
        f"objective {study.trials[0].value:.3g} at the start, "
        f"{study.best_value:.3g} at the best (trial {study.best_trial.number}). Calibrated: trial {best.number} "
        f"({best.value:.3g}), of the {len(contenders)} best the one scoring lowest on {draws} other draws of "
        f"the search's scenes ({min(c[2] for c in contenders):.3g}; the others "
        f"{', '.join(f'{c[2]:.3g}' for c in contenders if c[0] != best.number) or 'none'}): a search's best owes "
        f"part of its lead to the draws it was fitted to. Measured in φ: {record['phi']}.", "",
        f"Below, {cfg.final_chips} renders of scenes no trial rendered (seed {cfg.seed + 1}) against the "
        f"{len(real.phi)} real chips.", "",
        f"φ-FID ratio to the real chips (1 = as close as real chips to each other): start {ratio['start']}, "
        f"calibrated {ratio['calibrated']}. Precision / recall in φ (recall: the share of real chips near some "
        f"render; low when the renders are alike): start {pr['start']}, calibrated {pr['calibrated']}. "
        f"Told from the real chips by a small CNN (the two-sample test of `sasmi evaluate`, ROC AUC; 0.5 = it cannot): "
        f"start {told['start']}, calibrated {told['calibrated']}.", "",
        *statistics_table(real, shown), "",
        *distribution_table(real, shown), "",
        *refinement_lines(refinement),
        *sensitivity_lines(pins, best.params, cfg.profile_trials), "",
        *together_lines(together, cfg.profile_trials), *([""] if together else []),
        "The calibrated preset: `preset.toml`. Real | start | calibrated: `sheet.png`. The objective over the "
        "search: `objective.png`." + (" The knobs that move together, trial by trial, and the ratio or product "
                                      "judged: `ridges.png`." if ridges else ""), "",
        "![sheet](sheet.png)", "", "![objective](objective.png)", "",
        *(["![ridges](ridges.png)", ""] if ridges else []),
    ]
    write_text(out / "report.md", "\n".join(lines))
