"""The one list of the pose methods and profiles of the ``make reproduce`` graph (base layer: no imports).

The reporting layer (:mod:`sixdpose.reporting`: tables, README blocks, the paper's rows), the comparisons
of the notebooks and the check of ``mk/reproduce.mk`` / ``mk/profiles.mk`` (``tests/test_layers.py``) all
read these tuples; nothing else lists the methods.

A method's ``command`` is the ``sixdpose`` subcommand and its arguments as the graph runs it, without the
data, mask and output arguments; ``{runs}`` stands for the profile's run directory (``runs/<profile>``)
and ``{workers}`` for the number of worker processes.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Method:
    """A pose method of the graph (one results file per split and mask source).

    Attributes:
        key: file-name key (``ransac_icp``). label: display name. kind: ``hybrid`` or ``learned``.
        command: the graph's command line (mk ``CMD_<key>``), see the module docstring.
        paper_acc: the paper's row label in Tables I and III (None: the paper has no such row).
        paper_fps: the paper's row label in Table II (None: no such row).
        few: one of the short list run by the ``smoke`` profile (mk ``FEW_METHODS``).
        preset: the registration preset of a hybrid method: ``default`` (ours, tuned on the validation
            split) or ``paper`` (the paper's section IV-B settings, ``register --preset paper``: the
            "paper settings, rerun" rows, mk ``PAPER_HYBRID``, run where the profile's ``PAPER_ROWS`` is yes).
    """

    key: str
    label: str
    kind: str
    command: str
    paper_acc: str | None = None
    paper_fps: str | None = None
    few: bool = False
    preset: str = "default"


#: The hybrid methods of the graph rerun with the paper's own settings (``--preset paper``): the paper's
#: Table III rows (RANSAC + ICP, FGR + ICP, Super4PCS) as (key of ours, label).
_PAPER_ROWS = (("ransac_icp", "RANSAC + ICP"), ("fgr_icp", "FGR + ICP"), ("super4pcs", "Super4PCS"))

#: The methods of the graph, in table order (ours, tuned; the paper-settings reruns; the learned ones).
METHODS: tuple[Method, ...] = (
    Method("ransac", "RANSAC", "hybrid", "register --method ransac --no-verify"),
    Method("ransac_icp", "RANSAC + ICP", "hybrid", "register --method ransac --icp --no-verify",
           "Ours Hybrid(RANSAC + ICP)", "Ours Hybrid(RANSAC + ICP)", few=True),
    Method("fgr", "FGR", "hybrid", "register --method fgr --no-verify", None, "Ours Hybrid(FGR)"),
    Method("fgr_icp", "FGR + ICP", "hybrid", "register --method fgr --icp --no-verify", "Ours Hybrid(FGR + ICP)"),
    Method("super4pcs", "Super4PCS", "hybrid", "register --method super4pcs --no-verify", "Ours Hybrid(Super4PCS)",
           "Ours Hybrid(Super4PCS)", few=True),
    Method("super4pcs_icp", "Super4PCS + ICP", "hybrid", "register --method super4pcs --icp --no-verify"),
    *(Method(f"{key}_paper", f"{label} (paper settings, rerun)", "hybrid",
             "register --method " + key.replace("_icp", "") + (" --icp" if key.endswith("_icp") else "")
             + " --no-verify --preset paper", preset="paper")
      for key, label in _PAPER_ROWS),
    Method("learned_it0", "learned, no refinement", "learned", "predict-pose --pose {runs}/pose --iterations 0",
           "Ours Full Learning (No Refinement)", "Ours Full Learning (No Refinement)", few=True),
    Method("learned_it2", "learned + 2 refinement it.", "learned",
           "predict-pose --pose {runs}/pose --refiner {runs}/refiner --iterations 2", "Ours Full Learning (Iterative)",
           "Ours Full Learning", few=True),
    Method("learned_it2_icp", "learned + 2 it. + ICP", "learned",
           "predict-pose --pose {runs}/pose --refiner {runs}/refiner --iterations 2 --icp"),
    Method("learned_it2_colour", "learned + 2 it. + colour verification", "learned",
           "predict-pose --pose {runs}/pose --refiner {runs}/refiner --iterations 2 --colour-verify"),
    # the project's own method beside the paper's: the dense head (per-point object coordinates + a robust
    # fit), trained on the same data with mk DENSE_<profile>'s recipe (that of the synthetic-to-real dense head)
    Method("dense", "dense head", "learned", "predict-pose --pose {runs}/pose_dense"),
    Method("dense_icp", "dense head + ICP", "learned", "predict-pose --pose {runs}/pose_dense --icp"),
    # + the hypothesis verification with the learned stage's defaults (registration.LEARNED_VERIFY)
    Method("dense_icp_verify", "dense head + ICP + verification", "learned",
           "predict-pose --pose {runs}/pose_dense --icp --verify"),
)
#: key -> :class:`Method`.
METHOD: dict[str, Method] = {m.key: m for m in METHODS}

#: The global registration algorithms of the hybrid methods and their display names (paper Tables I-III).
HYBRID_ALGORITHMS: dict[str, str] = {"ransac": "RANSAC", "fgr": "FGR", "super4pcs": "Super4PCS"}


@dataclass(frozen=True)
class RealMethod:
    """A method of the synthetic-to-real branch, scored on real frames (``<name>_gt_<key>.json``).

    Attributes:
        key: the method key after ``<name>_gt_``. label: display name.
        trained_on: the training data of a learned method (``""`` for a hybrid method, which needs none).
        command: the graph's command line (mk ``YCBV_CMD_<key>``), see the module docstring.
    """

    key: str
    label: str
    trained_on: str
    command: str

    @property
    def kind(self) -> str:
        """``hybrid`` or ``learned``."""
        return "learned" if self.trained_on else "hybrid"


#: The learned rows of the real-frames table, each trained once on kinect and once on ideal depth:
#: (key suffix, label, pose run-name suffix, further predict-pose arguments). ``{d}`` in the arguments
#: stands for the run-name suffix of the depth (``""`` or ``"_ideal"``); ``{runs}`` is left for the graph.
_LEARNED_REAL = (
    ("", "learned", "", ""),
    ("_e12", "learned, 12 epochs", "_e12", ""),
    ("_it2", "learned + 2 refinement it.", "", " --refiner {runs}/refiner_ycbv{d} --iterations 2"),
    ("_jitter", "learned, colour jitter 0.3", "_jitter", ""),
    ("_icp", "learned + ICP", "", " --icp"),
    ("_colour", "learned + colour verification", "", " --colour-verify"),
)
#: The dense head's rows (the project's own method, trained once, on kinect depth, with the sim-to-real
#: augmentation of mk ``YCBV_DENSE_<profile>``): (key suffix, label, further predict-pose arguments).
_DENSE_REAL = (
    ("", "dense head", ""),
    ("_icp", "dense head + ICP", " --icp"),
    ("_verify", "dense head + verification", " --verify"),
    ("_icp_verify", "dense head + ICP + verification", " --icp --verify"),
)
#: The rows of the real-frames table, in table order: each learned variant on kinect, then on ideal
#: depth; the dense head's rows; then the hybrid methods with ICP, and the best of them (Super4PCS) with
#: the verification stage.
REAL_METHODS: tuple[RealMethod, ...] = (
    *(
        RealMethod(f"learned{d}{suffix}", label, trained_on,
                   f"predict-pose --pose {{runs}}/pose_ycbv{d}{run}" + more.replace("{d}", d))
        for suffix, label, run, more in _LEARNED_REAL
        for d, trained_on in (("", "ycbv (kinect depth)"), ("_ideal", "ycbv_ideal (ideal depth)"))
    ),
    *(
        RealMethod(f"dense{suffix}", label, "ycbv (kinect depth)",
                   f"predict-pose --pose {{runs}}/pose_ycbv_dense{more}")
        for suffix, label, more in _DENSE_REAL
    ),
    *(
        RealMethod(f"{algo}_icp", f"{name} + ICP", "",
                   f"register --method {algo} --icp --no-verify --workers {{workers}} --min-px 0")
        for algo, name in HYBRID_ALGORITHMS.items()
    ),
    RealMethod("super4pcs_icp_verify", "Super4PCS + ICP + verification", "",
               "register --method super4pcs --icp --verify --workers {workers} --min-px 0"),
)

#: The profiles of the ``make reproduce`` graph (mk/profiles.mk ``PROFILES``), smallest first.
GRAPH_PROFILES: tuple[str, ...] = ("smoke", "demo", "cpu", "paper")

#: The training profiles of the learned stages (``train-seg``, ``train-pose``, ``train-refiner --profile``).
STAGE_PROFILES: tuple[str, ...] = ("smoke", "cpu", "paper")
