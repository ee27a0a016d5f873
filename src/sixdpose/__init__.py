"""sixdpose: reproducible 6D object pose estimation from RGB-D images.

Stages (one sub-package each): ``assets`` (YCB models), ``generation`` (Drake synthetic data),
``datasets`` (readers: synthetic layout and BOP), ``segmentation`` (Mask R-CNN),
``registration`` (hybrid pose: RANSAC/FGR/Super4PCS + ICP),
``evaluation`` (ADD(-S), timing).
"""

__version__ = "0.1.0"
