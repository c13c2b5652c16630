"""One-call entry points for Python users (the rawpy-style quick start).

>>> import simcam
>>> rgb = simcam.render("photo.dng")      # doctest: +SKIP
>>> raw = simcam.read("photo.dng")        # doctest: +SKIP

Heavy modules are imported inside the functions, so ``import simcam`` stays light.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any


def read(path: str | Path, *, normalize: bool = True):
    """Read a raw DNG as a :class:`~simcam.frame.RawFrame`.

    Parameters
    ----------
    path : path
        The DNG file.
    normalize : bool
        Subtract the black level and divide by white - black (the DNG's linearization table,
        per-site black levels and deltas applied), giving normalised raw in which 1.0 is white;
        ``False`` keeps the stored DN.

    Returns
    -------
    RawFrame
        ``.data`` (float32 H x W mosaic), ``.meta`` (every tag simcam uses), ``.kind``.

    Examples
    --------
    >>> import simcam
    >>> examples = Path(simcam.__file__).resolve().parents[1] / "examples"
    >>> raw = read(examples / "data" / "chart.dng", normalize=False)
    >>> raw.kind, raw.data.dtype.name
    ('raw_dn', 'float32')
    """
    from .io.dng import read_dng

    frame = read_dng(path)
    if not normalize:
        return frame
    from .stages.raw import Normalize

    return Normalize()(frame)


def render(path: str | Path, pipeline: str | Path = "srgb", *, overrides: dict[str, Any] | None = None,
           seed: int | None = 0):
    """Render a raw DNG through a pipeline and return the pixels.

    Parameters
    ----------
    path : path
        The DNG file.
    pipeline : str or path
        A built-in pipeline (``"srgb"``, ``"linear-srgb"``, ``"sidd-srgb"``) or a YAML file.
    overrides : dict, optional
        ``{"stage.param": value}`` as ``simcam render --set`` takes them
        (``{"white_balance.source": "neutral"}``, nested: ``{"noise.model.beta1": 1e-3}``).
    seed : int, optional
        Seed of random stages (``noise``).

    Returns
    -------
    numpy.ndarray
        float32, H x W x 3 (H x W for raw outputs): display sRGB in [0, 1] for ``srgb`` (multiply
        by 255 and round for 8-bit), scene-linear for ``linear-srgb``.

    Examples
    --------
    >>> import simcam
    >>> from pathlib import Path
    >>> chart = Path(simcam.__file__).resolve().parent.parent / "examples" / "data" / "chart.dng"
    >>> rgb = render(chart)
    >>> rgb.ndim, rgb.shape[2], rgb.dtype.name, float(rgb.min()) >= 0.0, float(rgb.max()) <= 1.0
    (3, 3, 'float32', True, True)
    """
    from .io.dng import read_dng
    from .pipeline import Pipeline

    pipe = Pipeline.from_yaml(pipeline)
    if overrides:
        pipe = pipe.with_overrides(overrides)
    return pipe(read_dng(path), seed=seed).data
