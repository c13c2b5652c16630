"""Classes registered by their ``type`` name: the noise models, the noise effects and the pipeline stages.

A :class:`Registry` is a dict ``{type name: class}`` that refuses a second class under a taken name;
each family keeps one (``simcam.noise.base``, ``simcam.noise.effects.base``, ``simcam.stages.base``),
filled by its class decorator as the modules that define the classes are imported.
"""

from __future__ import annotations


class Registry(dict):
    """Classes by ``type`` name, each name taken once.

    Parameters
    ----------
    noun : str
        What the classes are (``"stage type"``), for the error on a name taken twice.
    name_both : bool
        Name both classes in that error.

    Attributes
    ----------
    noun, name_both
        As the parameters; the registry itself maps each name to its class.

    Examples
    --------
    >>> stages = Registry("stage type", name_both=True)
    >>> class Gamma: ...
    >>> stages.add("gamma", Gamma) is Gamma, stages.types()
    (True, {'gamma': <class 'simcam.registry.Gamma'>})
    >>> class Other: ...
    >>> stages.add("gamma", Other)
    Traceback (most recent call last):
    ...
    TypeError: stage type 'gamma' registered twice (Gamma, Other)
    """

    def __init__(self, noun: str, *, name_both: bool = False):
        super().__init__()
        self.noun, self.name_both = noun, name_both

    def add(self, key: str, cls: type) -> type:
        """Register ``cls`` under ``key`` (again for the same class is a no-op) and return it."""
        old = self.get(key)
        if old is not None and old is not cls:
            both = f" ({old.__name__}, {cls.__name__})" if self.name_both else ""
            raise TypeError(f"{self.noun} {key!r} registered twice{both}")
        self[key] = cls
        return cls

    def types(self) -> dict[str, type]:
        """A copy: ``{type name: class}``."""
        return dict(self)
