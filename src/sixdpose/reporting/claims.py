"""The paper's claims, each set against the figures of our result files, with a verdict computed by a rule.

Every claim below is a sentence of the paper (``../shared/paper/paper.txt``; the section is given) that our
results can speak to. For each, :func:`claims` reads the result files of a profile (``results/<profile>/``,
through :mod:`sixdpose.reporting.report`'s readers), states the figures it compares and decides:

* ``supported`` / ``contradicted``: the figures differ in the claimed / the opposite direction by more than
  their noise. Accuracies are proportions of GT instances, so the noise of a difference of two accuracies
  is taken as :data:`Z_DECIDE` binomial standard errors, ``Z * sqrt(p_a (1 - p_a) / n_a + p_b (1 - p_b) /
  n_b)``. Frame rates have no such model: a ratio beyond :data:`FPS_RATIO` decides.
* ``inconclusive``: the difference is within the noise, the results needed are missing (the reason is
  given), or the experiment was too short to decide (the ablation of 300 steps per variant on one seed:
  its rows say so).

Nothing here is tuned to a verdict: the rules are fixed above, and the table prints the figures beside the
verdict so a reader can apply another rule.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from ..artifacts.tables import write_table
from ..registry import METHOD, METHODS
from .paper import TABLES
from .report import ABLATIONS, TABLE2_BENCH, _optional, ablation_table, load_entries

#: Standard errors a difference of two accuracies must exceed to decide (about a 95 % two-sided test).
Z_DECIDE = 2.0
#: Frame-rate ratio beyond which one method counts as faster (timings on a shared machine vary by ~20 %).
FPS_RATIO = 1.25
#: Seeds an ablation needs per variant before its spread is trusted.
MIN_SEEDS = 3
#: The verdicts, in the order the table explains them.
VERDICTS = ("supported", "contradicted", "inconclusive")


@dataclass(frozen=True)
class Claim:
    """One claim of the paper and what our results say.

    Attributes:
        key: short name. claim: the paper's claim (paraphrased closely). where: its section of the paper.
        figure: our figures that bear on it (text with numbers). verdict: one of :data:`VERDICTS`, with
        ``why``: the rule's outcome in words.
    """

    key: str
    claim: str
    where: str
    figure: str
    verdict: str
    why: str


def decide(a: float, n_a: int, b: float, n_b: int) -> tuple[float, float]:
    """``(a - b, margin)`` for two accuracies in % over ``n_a`` / ``n_b`` instances: the difference in points
    and :data:`Z_DECIDE` binomial standard errors of it (points)."""
    pa, pb = a / 100.0, b / 100.0
    se = math.sqrt(pa * (1 - pa) / max(n_a, 1) + pb * (1 - pb) / max(n_b, 1))
    return a - b, 100.0 * Z_DECIDE * se


def _direction(d: float, margin: float, claimed_positive: bool = True) -> tuple[str, str]:
    if abs(d) <= margin:
        return "inconclusive", f"difference {d:+.2f} points within the noise (+-{margin:.2f})"
    positive = d > 0
    verdict = "supported" if positive == claimed_positive else "contradicted"
    return verdict, f"difference {d:+.2f} points beyond the noise (+-{margin:.2f})"


def _acc(entries: dict, name: tuple) -> tuple[float, int] | None:
    e = entries.get(name)
    if e is None or e.figure("accuracy") is None or not e.figure("n_gt"):
        return None
    return e.figure("accuracy"), int(e.figure("n_gt"))


def _missing(key, claim, where, what) -> Claim:
    return Claim(key, claim, where, f"no result: {what}", "inconclusive", "the results it needs are not here")


def _pair_claim(entries, key, claim, where, better: tuple, worse: tuple, label: str) -> Claim:
    """A claim that ``better`` (a graph result key) scores above ``worse``."""
    a, b = _acc(entries, better), _acc(entries, worse)
    if a is None or b is None:
        return _missing(key, claim, where, " and ".join("_".join(k) for k in (better, worse)))
    d, margin = decide(a[0], a[1], b[0], b[1])
    verdict, why = _direction(d, margin)
    return Claim(key, claim, where, f"{label}: {a[0]:.2f} % against {b[0]:.2f} % ({a[1]} GT instances)", verdict, why)


def _best(entries: dict, split: str, masks: str, kind: str) -> tuple[str, float, int] | None:
    """The most accurate method of ``kind`` (ours, preset default) on ``split`` / ``masks``."""
    cands = [(a[0], a[1], m.key) for m in METHODS if m.kind == kind and m.preset == "default"
             for a in [_acc(entries, (split, masks, m.key))] if a is not None]
    if not cands:
        return None
    acc, n, key = max(cands)
    return key, acc, n


def _ablation_rows(results_dir: Path, profile: str) -> tuple[str, list[dict]]:
    """``(name, rows)``: the first of :data:`~.report.ABLATIONS` that has run for ``profile`` (over seeds, else
    the one-seed ablation), its rows as :func:`~.report.ablation_table` reads them; no rows when neither has."""
    for name in ABLATIONS:
        rows = ablation_table(results_dir, profile, name)
        if rows:
            return f"{name}_{profile}", rows
    return f"{ABLATIONS[-1]}_{profile}", []


def refiner_noise(results_dir: Path, profile: str, entries: dict) -> Claim:
    """Section IV-C5: the pose noise added when training the refiner makes refinement significantly more
    effective. Needs an ablation with a refiner trained without noise; without one, the refinement's gain
    (trained with noise) is shown and the verdict is inconclusive."""
    key, claim, where = ("refiner_noise", "Training the refiner on noisy poses makes refinement significantly "
                         "more effective (not ablated in the paper)", "IV-C5")
    name, rows = _ablation_rows(results_dir, profile)
    rows = [r for r in rows if r.get("network") == "refiner" and r.get("val_add") is not None]
    it2, it0 = _acc(entries, ("test", "gt", "learned_it2")), _acc(entries, ("test", "gt", "learned_it0"))
    fig = ("refinement (refiner trained with noise) on the multi-instance split, GT masks: "
           f"{it0[0]:.2f} % -> {it2[0]:.2f} %" if it2 is not None and it0 is not None else "no refinement results")
    noisy = [r for r in rows if "without" not in str(r["variant"]).lower()]
    clean = [r for r in rows if "without" in str(r["variant"]).lower()]
    if not noisy or not clean:
        return Claim(key, claim, where, fig, "inconclusive",
                     f"no refiner trained without noise in {name} (not ablated)")
    a, b = noisy[0], clean[0]
    seeds = min(int(a.get("seeds") or 1), int(b.get("seeds") or 1))
    fig += (f"; ablation ({seeds} seed(s), val, 2 iterations): with noise {float(a['val_add']):.2f} +- "
            f"{float(a.get('val_add_std') or 0):.2f} %, without {float(b['val_add']):.2f} +- "
            f"{float(b.get('val_add_std') or 0):.2f} %")
    if seeds < MIN_SEEDS:
        return Claim(key, claim, where, fig, "inconclusive", f"fewer than {MIN_SEEDS} seeds per variant in {name}")
    spread = float(a.get("val_add_std") or 0) + float(b.get("val_add_std") or 0)
    verdict, why = _direction(float(a["val_add"]) - float(b["val_add"]), spread)
    return Claim(key, claim, where, fig, verdict, f"mean over {seeds} seeds against the spread: {why}")


def normalisation(results_dir: Path, profile: str, entries: dict) -> Claim:
    """Section IV-C3: normalisation layers make the translation hard to learn and the model ineffective.
    From the ablation ``pose_ablation_<profile>``: each variant with a norm layer against the same variant
    without; decided only with :data:`MIN_SEEDS` seeds and training long enough that the baseline learns."""
    key, claim, where = ("normalisation", "Normalisation layers make translation hard to learn and the model "
                         "ineffective; the paper removes them", "IV-C3")
    name, rows = _ablation_rows(results_dir, profile)
    rows = [r for r in rows if r.get("val_add") is not None and r.get("network") == "pose"]
    if not rows:
        return _missing(key, claim, where, name)
    base = {(r["translation"], r["rotation"]): r for r in rows if r.get("norm") == "none"}
    pairs = [(r, base[(r["translation"], r["rotation"])]) for r in rows
             if r.get("norm") not in (None, "none") and (r["translation"], r["rotation"]) in base]
    if not pairs:
        return _missing(key, claim, where, "a variant with and without a norm layer")
    pm = lambda r: f" +- {float(r['val_add_std']):.2f}" if r.get("val_add_std") else ""  # noqa: E731
    fig = "; ".join(f"{r['norm']} norm, {r['translation']} t: {r['val_add']:.2f}{pm(r)} % against "
                    f"{b['val_add']:.2f}{pm(b)} % without" for r, b in pairs)
    steps = {r.get("steps") for r in rows}
    seeds = min((int(r.get("seeds") or 1) for r in rows), default=1)
    dead = [b for _, b in pairs if float(b["val_add"]) == 0.0]
    if seeds < MIN_SEEDS or dead:
        why = (f"ablation too short: {'/'.join(str(s) for s in sorted(steps, key=str))} steps per variant, "
               f"{seeds} seed(s)" + (f", {len(dead)} baseline(s) at 0 %" if dead else ""))
        return Claim(key, claim, where, fig, "inconclusive", why)
    verdicts = []
    for r, b in pairs:  # with seeds, each row's val_add is the mean and val_add_std the spread
        spread = float(r.get("val_add_std") or 0) + float(b.get("val_add_std") or 0)
        verdicts.append(_direction(float(b["val_add"]) - float(r["val_add"]), spread)[0])
    verdict = verdicts[0] if len(set(verdicts)) == 1 else "inconclusive"
    return Claim(key, claim, where, fig, verdict, f"mean over {seeds} seeds against the spread: {', '.join(verdicts)}")


def hybrids_on_real_data(results_dir: Path, profile: str, entries: dict) -> Claim:
    """Section V-D: with a real depth camera the hybrid methods would likely fail as they do on LM-O.
    Failing = no better than the paper's best hybrid row on LM-O (its Table I); our hybrid methods on the
    real YCB-Video frames (``ycbv_gt_*``, GT masks) and on the test split with the kinect depth model."""
    key, claim, where = ("hybrids_real", "Hybrid methods would fail on real sensor data as they do on LM-O", "V-D")
    level = max(v for k, v in TABLES["I"].rows.items() if k.startswith("Ours Hybrid"))
    found = []
    for name in ("ycbv_gt_ransac_icp", "ycbv_gt_fgr_icp", "ycbv_gt_super4pcs_icp", "test_kinect_gt_ransac_icp",
                 "test_kinect_gt_super4pcs_icp"):
        r = _optional(results_dir, name)
        if r is not None and r.figures.get("accuracy") is not None:
            found.append((name, float(r.figures["accuracy"]), int(r.figures.get("n_gt") or 0)))
    if not found:
        return _missing(key, claim, where, "ycbv_gt_* or test_kinect_gt_* hybrid results")
    fig = ("; ".join(f"{n.replace('_gt_', ' ')}: {a:.2f} % of {k}" for n, a, k in found)
           + f" (GT masks; real YCB-Video frames and the kinect depth model, not LM-O); the paper's best hybrid "
             f"on LM-O: {level:.2f} %")
    margins = [decide(a, k, level, k) for _, a, k in found]  # the paper's figure treated as a proportion alike
    above = [d > m for d, m in margins]
    below = [d <= -m for d, m in margins]
    if all(above):
        return Claim(key, claim, where, fig, "contradicted",
                     "every hybrid result on real or sensor-model depth is above the paper's failure level")
    if all(below):
        return Claim(key, claim, where, fig, "supported", "every hybrid result is at or below that level")
    return Claim(key, claim, where, fig, "inconclusive", "the results fall on both sides of that level")


def _gpu(result) -> bool:
    """Whether the machine that wrote ``result`` had a GPU (its provenance's hardware)."""
    return bool(((result.provenance or {}).get("hardware") or {}).get("gpus"))


def learned_faster(results_dir: Path, profile: str, entries: dict) -> Claim:
    """Abstract and section VI: GPU-accelerated learned methods are faster than the hybrid ones (Super4PCS
    painfully slow). Learned + 2 refinement iterations against the fastest hybrid method: end to end with
    Mask R-CNN (the benchmark ``table2_fps``) when it ran, and the pose stage as the graph timed it on the
    multi-instance split with GT masks. The claim is about GPUs: measured without one, it is inconclusive
    (the figures still show the ratio on the CPU)."""
    key, claim, where = ("learned_faster", "Learned methods, GPU-accelerated, are faster than the hybrid ones",
                         "abstract, VI")
    sources = []  # (what, {method key: fps}, had a GPU)
    bench = _optional(results_dir, TABLE2_BENCH)
    if bench is not None:
        sources.append(("end to end with Mask R-CNN (table2_fps)",
                        {str(r["method"]): float(r["e2e_fps"]) for r in bench.rows if r.get("e2e_fps")}, _gpu(bench)))
    graph = {k[2]: e for k, e in entries.items() if k[:2] == ("test", "gt") and e.figure("fps")}
    sources.append(("pose stage, multi-instance split, GT masks", {k: e.figure("fps") for k, e in graph.items()},
                    any(_gpu(e.result) for e in graph.values())))
    figs, decided = [], []
    for what, fps, gpu in sources:
        hyb = {k: v for k, v in fps.items() if k in METHOD and METHOD[k].kind == "hybrid"}
        learned = fps.get("learned_it2")
        if learned is None or not hyb:
            continue
        fast = max(hyb, key=lambda k: hyb[k])
        ratio = learned / hyb[fast]
        figs.append(f"{what}: learned + 2 it. {learned:.3g} FPS, fastest hybrid {METHOD[fast].label} "
                    f"{hyb[fast]:.3g} FPS (ratio {ratio:.2f}, {'GPU' if gpu else 'CPU only'})")
        decided.append((ratio, gpu))
    if not figs:
        return _missing(key, claim, where, "the FPS of learned_it2 and of a hybrid method")
    ratio, gpu = decided[0]
    if not gpu:
        return Claim(key, claim, where, "; ".join(figs), "inconclusive",
                     "measured without a GPU (the claim is about GPU-accelerated networks)")
    if ratio > FPS_RATIO:
        return Claim(key, claim, where, "; ".join(figs), "supported", f"ratio above {FPS_RATIO}")
    if ratio < 1 / FPS_RATIO:
        return Claim(key, claim, where, "; ".join(figs), "contradicted", f"ratio below 1/{FPS_RATIO}")
    return Claim(key, claim, where, "; ".join(figs), "inconclusive", f"ratio within {FPS_RATIO} either way")


def super4pcs_best_hybrid(results_dir: Path, profile: str, entries: dict) -> Claim:
    """Abstract and section V: among the conventional methods only Super4PCS performs well."""
    key, claim, where = ("super4pcs", "Super4PCS is the best hybrid method", "abstract, V")
    for split, masks in (("single", "pred"), ("test", "gt"), ("test", "pred"), ("single", "gt")):
        found = {k: acc for k in ("super4pcs", "super4pcs_icp", "ransac", "ransac_icp", "fgr", "fgr_icp")
                 if (acc := _acc(entries, (split, masks, k))) is not None}
        s4 = max(((v, k) for k, v in found.items() if k.startswith("super4pcs")), default=None)
        other = max(((v, k) for k, v in found.items() if not k.startswith("super4pcs")), default=None)
        if s4 is not None and other is not None:
            (a, n_a), ka = s4
            (b, n_b), kb = other
            d, margin = decide(a, n_a, b, n_b)
            verdict, why = _direction(d, margin)
            return Claim(key, claim, where, f"{split} split, {masks} masks: {METHOD[ka].label} {a:.2f} % against "
                         f"{METHOD[kb].label} {b:.2f} % ({n_a} GT instances)", verdict, why)
    return _missing(key, claim, where, "Super4PCS and another hybrid method on one split")


def hybrid_beats_learned(results_dir: Path, profile: str, entries: dict) -> Claim:
    """Section V-D, Table III: on the generated data the hybrid methods beat the learned ones."""
    key, claim, where = ("hybrid_beats_learned", "On the generated (noise-free) data hybrid methods are more "
                         "accurate than learned ones", "V-D, Table III")
    for split, masks in (("single", "pred"), ("test", "gt"), ("test", "pred"), ("single", "gt")):
        h, lrn = _best(entries, split, masks, "hybrid"), _best(entries, split, masks, "learned")
        if h and lrn:
            d, margin = decide(h[1], h[2], lrn[1], lrn[2])
            verdict, why = _direction(d, margin)
            return Claim(key, claim, where, f"{split} split, {masks} masks: best hybrid {METHOD[h[0]].label} "
                         f"{h[1]:.2f} %, best learned {METHOD[lrn[0]].label} {lrn[1]:.2f} %", verdict, why)
    return _missing(key, claim, where, "a hybrid and a learned result on one split")


def claims(results_dir: str | Path, profile: str) -> list[Claim]:
    """Every claim of the paper our results speak to, with its figures and verdict (see the module
    docstring), from the result files of ``results_dir``.

    Raises:
        ResultError: a result file is corrupt (one line naming it).
    """
    results_dir = Path(results_dir)
    entries = load_entries(results_dir)
    out = [
        refiner_noise(results_dir, profile, entries),
        normalisation(results_dir, profile, entries),
        _pair_claim(entries, "refinement", "Iterative refinement improves the learned pose", "IV-C5, Table III",
                    ("test", "gt", "learned_it2"), ("test", "gt", "learned_it0"),
                    "multi-instance split, GT masks: 2 iterations against none"),
        _pair_claim(entries, "icp_learned", "ICP after a learned pose improves it (at a time cost)", "II",
                    ("test", "gt", "learned_it2_icp"), ("test", "gt", "learned_it2"),
                    "multi-instance split, GT masks: learned + 2 it. with ICP against without"),
        hybrid_beats_learned(results_dir, profile, entries),
        super4pcs_best_hybrid(results_dir, profile, entries),
        _pair_claim(_kinect_entries(results_dir, entries), "noise_free",
                    "The noise-free synthetic depth makes the hybrid methods' task much easier", "V-D, VI",
                    ("test", "gt", "super4pcs_icp"), ("test_kinect", "gt", "super4pcs_icp"),
                    "Super4PCS + ICP, ideal against kinect-model depth"),
        hybrids_on_real_data(results_dir, profile, entries),
        learned_faster(results_dir, profile, entries),
    ]
    return out


def _kinect_entries(results_dir: Path, entries: dict) -> dict:
    """``entries`` plus the kinect-depth hybrid results keyed like the graph's (``test_kinect``, ``gt``, key)."""
    from .report import Entry

    more = dict(entries)
    for m in METHODS:
        r = _optional(results_dir, f"test_kinect_gt_{m.key}")
        if r is not None:
            more[("test_kinect", "gt", m.key)] = Entry("test_kinect", "gt", m.key, r)
    return more


def _shown_dir(results_dir: str | Path) -> str:
    """``results_dir`` as the comment of the table names it: without leading ``..`` parts (notebook 07 runs
    in ``notebooks/`` and reads ``../results/<profile>``), so the file does not depend on where it was written."""
    parts = Path(results_dir).parts
    while parts and parts[0] == "..":
        parts = parts[1:]
    return str(Path(*parts)) if parts else "."


def write_claims(results_dir: str | Path, profile: str, csv_path, tex_path) -> list[Claim]:
    """Write :func:`claims` as CSV and LaTeX (``paper/generated/<profile>/claims.tex``; wrapped ``p{}``
    columns); returns the claims."""
    rows = claims(results_dir, profile)
    write_table([{"claim": c.claim, "where": c.where, "figure": c.figure, "verdict": c.verdict, "why": c.why}
                 for c in rows], ["claim", "where", "figure", "verdict", "why"], csv_path, tex_path,
                headers=["The paper's claim", "Section", "Our figures", "Verdict", "Rule's outcome"],
                align="p{0.18\\linewidth}p{0.07\\linewidth}p{0.32\\linewidth}p{0.09\\linewidth}p{0.18\\linewidth}",
                comment=f"generated by sixdpose.reporting.claims from {_shown_dir(results_dir)} (profile {profile})")
    return rows
