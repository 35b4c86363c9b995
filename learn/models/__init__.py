"""Compensator registry: ``make_model(kind, **hparams)``; ``MODELS`` maps kind -> class.

Built in (learn.models.base.BUILTIN_MODULES): mean, linear, cubic (classical), mlp, lstm, gru (neural),
tcn (ours), bp (velostat paper), bp_lm (fabric paper, Levenberg-Marquardt), rbf (ntype paper), map_cnn
(ntype, ours), ensemble (a seed ensemble of any of them). A new model registers itself with
``@register("name")`` in its own module, listed in BUILTIN_MODULES.
"""

from learn.models.base import (
    MODELS,
    Compensator,
    Streamer,
    edge_windows,
    load_builtin_models,
    make_model,
    register,
)

load_builtin_models()

__all__ = ["MODELS", "Compensator", "Streamer", "edge_windows", "make_model", "register"]
