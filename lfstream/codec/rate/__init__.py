"""Rate control: the configuration of a stream, chosen for a target size or by default.

The package is the data flow of that choice:

- :mod:`~lfstream.codec.rate.common`: what every choice shares (:class:`RateChoice`, the
  target's checks, a stream's size, the follower that holds a video to its budget);
- :mod:`~lfstream.codec.rate.default`: the default encode's choice on the first frame (no
  target): the centre's coding, the hint's resolution, or the views where no warp predicts;
- :mod:`~lfstream.codec.rate.search`: the searches (``full``: every configuration coded and
  decoded; ``quick``: the ``fast`` preset's);
- :mod:`~lfstream.codec.rate.model`: rate control as a model of bytes against quality (the
  default under a target, :func:`choose_rate`).
"""

from lfstream.codec.rate.common import (
    FOLLOW_DEADBAND,
    FOLLOW_MAX_STEP,
    FOLLOW_STEP_GROWTH,
    RATE_CONTROL_CHOOSES,
    RATE_TOLERANCE,
    SEARCHED,
    SEARCHES,
    RateChoice,
    follow_rate,
    rate_control_conflict,
    validate_target,
)
from lfstream.codec.rate.default import (
    DEFAULT_PRESET_BY_VIEWS,
    HINT_COARSEN_DB_PER_PERCENT,
    HINT_COARSEN_MAX_LOSS_DB,
    PREDICTION_CHECK_MIN_CELLS,
    PREDICTION_FLOOR_DB,
    DefaultChoice,
    choose_default,
    coarsening_allowance,
    default_preset,
    prediction_psnr,
    uses_default_choice,
)
from lfstream.codec.rate.follow import FRAME_CAP, FRAME_REDO, RateFollower, family_of
from lfstream.codec.rate.model import choose_rate, model_configuration
from lfstream.codec.rate.search import (
    COARSE_HINT_SCALE,
    PROBE_NEAR,
    QUICK_HINT_SHARE,
    QUICK_MAX_CENTRE_QUALITY,
    RESIDUAL_PRESET,
    RESIDUAL_SHARES,
    choose_configuration,
)

__all__ = ["RATE_CONTROL_CHOOSES", "rate_control_conflict", "validate_target",
           "RATE_TOLERANCE", "SEARCHES", "SEARCHED", "QUICK_MAX_CENTRE_QUALITY", "QUICK_HINT_SHARE", "PROBE_NEAR",
           "COARSE_HINT_SCALE", "RESIDUAL_SHARES", "RESIDUAL_PRESET", "FOLLOW_MAX_STEP",
           "FOLLOW_DEADBAND", "FOLLOW_STEP_GROWTH", "PREDICTION_FLOOR_DB", "PREDICTION_CHECK_MIN_CELLS",
           "HINT_COARSEN_MAX_LOSS_DB", "HINT_COARSEN_DB_PER_PERCENT", "coarsening_allowance",
           "DEFAULT_PRESET_BY_VIEWS", "default_preset", "RateChoice", "DefaultChoice",
           "choose_configuration", "choose_default", "choose_rate", "model_configuration", "uses_default_choice",
           "follow_rate", "prediction_psnr", "FRAME_CAP", "FRAME_REDO", "RateFollower", "family_of"]
