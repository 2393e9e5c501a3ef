"""sorjax: camera calibration from the outlines of surfaces of revolution, in JAX.

After K.-Y. K. Wong, P. R. S. Mendonca and R. Cipolla, "Camera Calibration from
Surfaces of Revolution", IEEE TPAMI 25(2), 2003.  Pixels follow OpenCV: the centre of
the top-left pixel is (0, 0), x to the right, y down.  Everything runs in float64.
"""

import jax as _jax

_jax.config.update("jax_enable_x64", True)

from ._calibration import RESULTS, Calibration, CalibrationError, calibrate  # noqa: E402
from ._extract import outlines_from_image, outlines_from_mask  # noqa: E402
from ._homology import Homology, fit_homology, homology_matrix  # noqa: E402
from ._image_outline import ImageOutline  # noqa: E402
from ._masks import MASK_OFFSET_PX  # noqa: E402
from ._outline import Outline, make_outline  # noqa: E402
from ._outline_files import load_outlines, save_outlines  # noqa: E402
from ._uncertainty import ErrorPrediction, predicted_error  # noqa: E402
from .core._options import Options  # noqa: E402
from . import losses, render, scenes  # noqa: E402

__all__ = [
    "RESULTS",
    "Calibration",
    "CalibrationError",
    "ErrorPrediction",
    "Homology",
    "ImageOutline",
    "MASK_OFFSET_PX",
    "Options",
    "Outline",
    "calibrate",
    "fit_homology",
    "homology_matrix",
    "load_outlines",
    "losses",
    "make_outline",
    "outlines_from_image",
    "outlines_from_mask",
    "predicted_error",
    "render",
    "save_outlines",
    "scenes",
]
