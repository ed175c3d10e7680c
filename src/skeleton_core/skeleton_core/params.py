"""One definition per parameter (no rclpy).

Every tunable value is declared once, as a field of a library configuration dataclass, with
:func:`param`::

    @dataclass
    class OptimizerConfig:
        w_style: float = param(8.0, 'Eq. 15: weight of the style term E_s', range=(0.0, 1000.0))

Everything else is derived from that declaration:

* the library's default and its validation (:func:`check`, called by the library class);
* the node's ROS parameters (:func:`specs`: name, default, description, range / choices,
  read-only) -> ``skeleton_core.rosnode.Parameters`` declares them with descriptors;
* the node's configuration object from its parameter values (:func:`build`);
* the YAML files in ``config/`` and ``docs/parameters.md`` (``kinect_experiments.param_docs``);
* the evaluation methods' defaults (:func:`defaults`).

A field declared ``public=False`` stays a validated, documented field of its configuration but is
not a ROS parameter of any node: it keeps its default in the running graph and is set only by a
named preset file (``config/presets/<name>.yaml``, :func:`load_preset`) that the evaluation and the
paper-table experiments load (e.g. the paper's own variant, ``shum2013``). A node declares only
the public ones (``skeleton_core.rosnode.Parameters``) and refuses a YAML key or ``-p`` naming any
other.

A field whose ROS parameter has another name (``Gains.ke`` -> ``kp``) says so with ``name=``; one
kept in radians but set in degrees on the node says ``degrees=True`` (the range and default of the
ROS parameter are then in degrees). A nested configuration (``SimConfig.gains``) is declared with
:func:`nested`; its parameters are flattened into the parent's.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, fields, is_dataclass
from pathlib import Path
from typing import Any, Callable, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple

import yaml

_KEY = 'param'


@dataclass
class ParamSpec:
    """One parameter: ROS name, default, description, and what is valid. ``path`` is the
    attribute path in its configuration dataclass (empty for a parameter of a node only);
    ``degrees``: the attribute is in radians, the parameter in degrees."""

    name: str
    default: Any
    description: str
    range: Optional[tuple] = None          # (lo, hi) inclusive, for int/float
    choices: Optional[Sequence[Any]] = None  # allowed values (strings, ints)
    read_only: bool = False
    validator: Optional[Callable[[Any], Optional[str]]] = None  # returns an error text or None
    path: Tuple[str, ...] = ()
    degrees: bool = False
    public: bool = True  # False: not a node parameter (a preset sets it; module docstring)

    def check(self, value: Any) -> Optional[str]:
        """An error text for ``value`` (in ROS units), or None."""
        if hasattr(value, 'tolist'):  # numpy scalar or array: plain Python values
            value = value.tolist()
        if isinstance(self.default, bool) != isinstance(value, bool):
            return f'{self.name} must be a bool'
        if isinstance(self.default, float) and isinstance(value, (int, float)):
            if not math.isfinite(float(value)):
                return f'{self.name} must be finite'
        if self.range is not None and isinstance(value, (int, float)) and not isinstance(value, bool):
            lo, hi = self.range
            if not (lo <= value <= hi):
                return f'{self.name}={value} is outside [{lo}, {hi}]'
        if self.choices is not None and value not in self.choices:
            return f'{self.name}={value!r} is not one of {list(self.choices)}'
        if self.validator is not None:
            err = self.validator(value)
            if err is not None and self.name not in err:
                err = f'{self.name}: {err}'
            return err
        return None

    def constraint_text(self) -> str:
        """``[lo, hi]`` / ``one of [...]`` / '' (for comments and docs)."""
        if self.range is not None:
            return f'[{self.range[0]}, {self.range[1]}]'
        if self.choices is not None:
            return f'one of {list(self.choices)}'
        return ''


def param(default: Any = dataclasses.MISSING, description: str = '', *,
          range: Optional[tuple] = None, choices: Optional[Sequence[Any]] = None,
          read_only: bool = False, name: Optional[str] = None, degrees: bool = False,
          validator: Optional[Callable[[Any], Optional[str]]] = None,
          public: bool = True) -> Any:
    """A dataclass field that is also a parameter (see the module docstring). A list default is
    copied for every instance. ``read_only``: the node cannot change it while running;
    ``public=False``: not a node parameter, set only by a preset."""
    meta = {_KEY: dict(description=description, range=range,
                       choices=None if choices is None else tuple(choices), read_only=read_only,
                       name=name, degrees=degrees, validator=validator, public=public)}
    if isinstance(default, list):
        return dataclasses.field(default_factory=lambda d=tuple(default): list(d), metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


def nested(cls: type) -> Any:
    """A field holding another configuration dataclass (its parameters join the parent's)."""
    return dataclasses.field(default_factory=cls, metadata={_KEY: dict(nested=True)})


def _ros_default(value: Any, degrees: bool) -> Any:
    if degrees:
        return math.degrees(value)
    if isinstance(value, tuple):
        return list(value)
    return value


def specs(cls: type, only: Optional[Iterable[str]] = None, exclude: Iterable[str] = (),
          prefix: str = '', read_only: Optional[bool] = None) -> List[ParamSpec]:
    """The parameters declared on ``cls`` (a dataclass; nested ones flattened), in declaration
    order, by ROS name, the public ones and those a preset sets (``public=False``; a node gives
    them all to ``rosnode.Parameters``, which declares only the public ones). ``only`` /
    ``exclude``: ROS names; ``prefix``: prepended to every name; ``read_only``: force the flag
    (e.g. True for values a node reads once at start-up)."""
    out: List[ParamSpec] = []
    _collect(cls, (), out)
    if only is not None:
        keep = list(only)
        missing = set(keep) - {s.name for s in out}
        if missing:
            raise KeyError(f'{cls.__name__} declares no parameter {sorted(missing)}')
        by_name = {s.name: s for s in out}
        out = [by_name[n] for n in keep]   # in the order asked for
    drop = set(exclude)
    out = [s for s in out if s.name not in drop]
    if prefix or read_only is not None:
        out = [dataclasses.replace(s, name=prefix + s.name,
                                   read_only=s.read_only if read_only is None else read_only)
               for s in out]
    return out


def _collect(cls: type, path: Tuple[str, ...], out: List[ParamSpec]) -> None:
    for f in fields(cls):
        meta = f.metadata.get(_KEY)
        if meta is None:
            continue
        if meta.get('nested'):
            _collect(f.default_factory, path + (f.name,), out)
            continue
        if f.default is not dataclasses.MISSING:
            default = f.default
        elif f.default_factory is not dataclasses.MISSING:
            default = f.default_factory()
        else:
            raise TypeError(f'{cls.__name__}.{f.name}: a parameter needs a default')
        out.append(ParamSpec(meta['name'] or f.name, _ros_default(default, meta['degrees']),
                             meta['description'], meta['range'], meta['choices'],
                             meta['read_only'], meta['validator'], path + (f.name,),
                             meta['degrees'], meta['public']))


def public(params: Iterable[ParamSpec]) -> List[ParamSpec]:
    """The node parameters among ``params`` (those not set by a preset only)."""
    return [s for s in params if s.public]


def hidden(spec: ParamSpec) -> ParamSpec:
    """``spec`` as a fixed value of its node, not a parameter (a node-only ParamSpec that
    keeps its name, default and description where the node's code reads it)."""
    return dataclasses.replace(spec, public=False)


def names(cls: type) -> List[str]:
    """ROS names of the parameters of ``cls``."""
    return [s.name for s in specs(cls)]


def defaults(cls: type, only: Optional[Iterable[str]] = None) -> Dict[str, Any]:
    """``{ROS name: default}`` of ``cls`` (e.g. an evaluation method's defaults)."""
    return {s.name: s.default for s in specs(cls, only=only)}


def _get(obj: Any, path: Tuple[str, ...]) -> Any:
    for p in path:
        obj = getattr(obj, p)
    return obj


def value_of(cfg: Any, spec: ParamSpec) -> Any:
    """The value of ``spec`` in the configuration object ``cfg``, in ROS units."""
    return _ros_default(_get(cfg, spec.path), spec.degrees)


def assign(cfg: Any, spec: ParamSpec, value: Any) -> None:
    """Set the field of ``spec`` in ``cfg`` from a ROS-unit ``value`` (no check)."""
    if spec.degrees:
        value = math.radians(value)
    elif isinstance(spec.default, float) and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    setattr(_get(cfg, spec.path[:-1]), spec.path[-1], value)


def build(cls: type, values: Mapping[str, Any], strict: bool = False) -> Any:
    """An instance of ``cls`` (defaults) with the parameters found in ``values`` (ROS names and
    units) set. Names ``cls`` does not declare are ignored, or refused when ``strict``."""
    cfg = cls()
    known = specs(cls)
    if strict:
        unknown = set(values) - {s.name for s in known}
        if unknown:
            raise ValueError(f'unknown {cls.__name__} parameters: {sorted(unknown)}')
    for s in known:
        if s.name in values:
            assign(cfg, s, values[s.name])
    return cfg


def check(cfg: Any, nested: bool = True) -> None:
    """Raise ValueError (one line) when a field of ``cfg`` is outside its declared range /
    choices or fails its validator. ``nested=False``: not the nested configurations' fields."""
    if not is_dataclass(cfg):
        raise TypeError('check() needs a configuration dataclass instance')
    for s in specs(type(cfg)):
        if not nested and len(s.path) > 1:
            continue
        err = s.check(value_of(cfg, s))
        if err is not None:
            raise ValueError(err)


def split(values: Mapping[str, Any], *classes: type) -> Tuple[Dict[str, Any], ...]:
    """``values`` divided by which of ``classes`` declares each name (one dict per class, then
    one of the names no class declares)."""
    out: List[Dict[str, Any]] = [{} for _ in classes]
    rest: Dict[str, Any] = {}
    sets = [set(names(c)) for c in classes]
    for k, v in values.items():
        for d, s in zip(out, sets):
            if k in s:
                d[k] = v
                break
        else:
            rest[k] = v
    return (*out, rest)


class PresetError(ValueError):
    """A preset file that cannot be used (one line)."""


def load_preset(path: Any, classes: Sequence[type]) -> Dict[str, Any]:
    """``{parameter name: value}`` of the preset YAML file ``path`` (a flat mapping), every name
    declared (publicly or not) by one of ``classes`` and every value valid for it. Raises
    :class:`PresetError` naming the file and the first bad entry."""
    p = Path(path)
    try:
        data = yaml.safe_load(p.read_text())
    except OSError as e:
        raise PresetError(f'cannot read preset {str(p)!r}: {e.strerror or e}') from None
    except yaml.YAMLError as e:
        raise PresetError(f'preset {str(p)!r} is not valid YAML: '
                          f'{str(e).splitlines()[0]}') from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise PresetError(f'preset {str(p)!r} must be a mapping of parameter names to values')
    known: Dict[str, ParamSpec] = {}
    for cls in classes:
        for s in specs(cls):
            known.setdefault(s.name, s)
    out: Dict[str, Any] = {}
    for k, v in data.items():
        s = known.get(k)
        if s is None:
            raise PresetError(f'preset {str(p)!r}: unknown parameter {k!r}')
        if isinstance(s.default, float) and isinstance(v, int) and not isinstance(v, bool):
            v = float(v)
        err = s.check(v)
        if err is not None:
            raise PresetError(f'preset {str(p)!r}: {err}')
        out[k] = v
    return out
