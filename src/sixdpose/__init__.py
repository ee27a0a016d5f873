"""sixdpose: reproducible 6D object pose estimation from RGB-D images.

Stages (one sub-package each): ``assets`` (YCB models), ``generation`` (Drake synthetic data),
``datasets`` (readers: synthetic layout and BOP), ``segmentation`` (Mask R-CNN),
``registration`` (hybrid pose: RANSAC/FGR/Super4PCS + ICP), ``pose`` (the learned pose network),
``evaluation`` (ADD(-S), BOP scores, timing) and ``reporting`` (method comparisons, the paper's tables,
the README's generated blocks).

Layers, bottom to top; a module imports only its own layer and the ones below (``tests/test_layers.py``
checks this and that no import cycle exists between modules or packages):

1. base: ``errors``, ``constants`` (thresholds), ``registry`` (methods, profiles), ``geometry`` (``X_from``),
   ``schemas`` (file schemas), ``options`` (typed CLI options), ``graph`` (the make
   graph's files, for notebooks), ``workers`` (pool workers), ``lazy``, ``fileio``, ``config``, ``logs``, ``runs``;
2. readers and artifacts: ``datasets``, ``assets``, ``artifacts``;
3. scoring: ``evaluation``;
4. stages: ``generation``, ``segmentation``, ``registration``, ``pose`` (``pose`` uses ``registration``
   through its public names only);
5. reporting: ``reporting``;
6. command line: ``cli`` and each stage's ``<stage>.cli``.
"""

__version__ = "0.1.0"
