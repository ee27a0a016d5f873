"""The training schedule shared by every network's config, and its learning-rate rule.

:class:`TrainSchedule` holds the optimisation, budget and process fields that the pose, refiner and
segmentation configs have in common; each of them derives from it (so ``--set epochs=6``,
``--set lr=1e-4``, ``--set time_budget=0`` and the flat keys of every saved ``config.json`` keep
working) and only re-declares the defaults that differ.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..config import Config, bounded

#: Schedule fields a ``--resume`` may change (they do not alter what an epoch computes).
RESUMABLE = ("epochs", "time_budget", "num_threads", "num_workers", "log_every")


@dataclass(frozen=True)
class TrainSchedule(Config):
    """Optimisation schedule, budgets and processes of a training run (base of every training config).

    Fields:
        epochs: epochs to train. batch_size: items (images) per step and process.
        lr: Adam learning rate. weight_decay: Adam weight decay.
        warmup_steps: exponential warm-up from lr/1000 to lr over the first global steps (0: none).
        lr_step_epochs, lr_gamma: learning rate x ``lr_gamma`` every ``lr_step_epochs`` epochs (a
            per-epoch StepLR; see :func:`learning_rate`).
        grad_clip: max gradient norm (0: off). amp: mixed precision (autocast + grad scaler, CUDA only).
        time_budget: seconds of training (0: none), summed over resumes and checked after every step:
            once spent, the rest of the epoch is skipped, the epoch is checkpointed as done and
            training stops with the final model.
        max_steps_per_epoch: cap on the steps of an epoch (0: full epochs).
        seed: initialisation, shuffling, sampling and augmentation.
        num_workers: data-loading worker processes. num_threads: torch CPU threads (0: torch default).
        log_every: steps between rows of ``metrics.csv``.
        ema_decay: exponential moving average of the weights (0: off). With ``d`` > 0 the engine keeps
            ``w_ema <- m w_ema + (1 - m) w`` after every step, ``m = min(d, (1 + n) / (10 + n))`` at global
            step ``n`` (the usual warm-up), buffers copied; ``model.pt`` holds the averaged weights and
            ``last.pt`` both (its ``model`` the raw ones, to resume). It evens out the step-to-step wander
            of a small-batch run, so the final model depends less on where the budget stops it.
    """

    epochs: int = bounded(100, min=1, max=100_000)
    batch_size: int = bounded(8, min=1, max=1024)
    lr: float = bounded(1e-3, min=0, max=10, min_open=True)
    warmup_steps: int = bounded(0, min=0, max=100_000_000)
    lr_step_epochs: int = bounded(10, min=1, max=100_000)
    lr_gamma: float = bounded(0.6, min=0, max=1, min_open=True)
    weight_decay: float = bounded(0.0, min=0, max=1)
    grad_clip: float = bounded(0.0, min=0, max=1e6)
    amp: bool = True
    time_budget: float = bounded(0.0, min=0, max=30 * 24 * 3600.0)
    max_steps_per_epoch: int = bounded(0, min=0, max=100_000_000)
    seed: int = bounded(0, min=0, max=2**32 - 1)
    num_workers: int = bounded(2, min=0, max=256)
    num_threads: int = bounded(0, min=0, max=1024)
    log_every: int = bounded(10, min=1, max=1_000_000)
    ema_decay: float = bounded(0.0, min=0, max=1, max_open=True)


def ema_momentum(decay: float, step: int) -> float:
    """Momentum of the weight average after global step ``step`` (0-based): ``min(decay, (1 + step) / (10 +
    step))``, so the first steps' random initial weights fade fast (:attr:`TrainSchedule.ema_decay`)."""
    return min(decay, (1.0 + step) / (10.0 + step))


def learning_rate(cfg: TrainSchedule, epoch: int, step: int) -> float:
    """Learning rate of global ``step`` (0-based) in ``epoch`` (0-based).

    ``lr * lr_gamma ** (epoch // lr_step_epochs) * w(step)`` with the exponential warm-up
    ``w(s) = 1000 ** (s / warmup_steps - 1)`` for ``s < warmup_steps`` (then 1).
    """
    lr = cfg.lr * cfg.lr_gamma ** (epoch // cfg.lr_step_epochs)
    if cfg.warmup_steps and step < cfg.warmup_steps:
        lr *= 1000.0 ** (step / cfg.warmup_steps - 1.0)
    return lr
