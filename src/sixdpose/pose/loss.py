"""The pose loss of paper eq. (1)/(2) (also the ADD(-S) metric of eq. (4)), batched, in torch."""

from __future__ import annotations

import torch


def transform(points_O: torch.Tensor, R: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """``R p + t`` for batched points: (N, M, 3), (N, 3, 3), (N, 3) -> (N, M, 3)."""
    return torch.bmm(points_O, R.transpose(1, 2)) + t[:, None, :]


def pose_loss(R_pred: torch.Tensor, t_pred: torch.Tensor, R_gt: torch.Tensor, t_gt: torch.Tensor,
              model_points: torch.Tensor, symmetric: torch.Tensor) -> torch.Tensor:
    """Per-instance ADD (asymmetric, eq. 1) or one-directional chamfer (symmetric, eq. 2), metres.

    ``ADD = mean_j ||(R x_j + t) - (R^ x_j + t^)||``;
    ``chamfer = mean_j min_k ||(R x_j + t) - (R^ x_k + t^)||`` (``torch.cdist``).

    Args:
        R_pred, R_gt: (N, 3, 3). t_pred, t_gt: (N, 3) metres. model_points: (N, M, 3) object-frame
            points (metres). symmetric: (N,) bool.
    Returns:
        (N,) losses in metres (average them for the optimiser).
    """
    gt = transform(model_points, R_gt, t_gt)
    pred = transform(model_points, R_pred, t_pred)
    add = (gt - pred).norm(dim=2).mean(dim=1)
    if bool(symmetric.any()):
        chamfer = torch.cdist(gt, pred).min(dim=2).values.mean(dim=1)
        add = torch.where(symmetric, chamfer, add)
    return add
