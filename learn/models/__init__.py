"""Compensator registry: ``make_model(kind, **hparams)``; ``MODELS`` maps kind -> class.

Built in: mean (trivial baseline), linear, cubic (learn.models.classical), mlp, lstm, gru
(learn.models.neural), tcn (ours, learn.models.tcn), ensemble (a seed ensemble of any of them,
learn.models.ensemble). Another family's models register themselves with
``@register("name")`` in their own module, imported here.
"""

from learn.models.base import MODELS, Compensator, Streamer, edge_windows, make_model, register
from learn.models import classical, neural, tcn  # noqa: F401,E402  (register)
from learn.models import velostat  # noqa: F401,E402  (register: bp)
from learn.models import bpnet  # noqa: F401,E402  (fabric: BP network trained by Levenberg-Marquardt)
from learn.models import map_cnn, rbf  # noqa: F401,E402  (ntype: rbf = the paper's RBFNN, map_cnn = ours)
from learn.models import ensemble  # noqa: F401,E402  (seed ensemble of any registered model)

__all__ = ["MODELS", "Compensator", "Streamer", "edge_windows", "make_model", "register"]
