"""The result of a sweep: Pi2 samples, impact counts and detected periods per grid point."""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass, field

import numpy as np

__all__ = ["SweepResult", "write_npz"]

_FORMAT = "grazing_control.sweep/1"


def write_npz(path, arrays: dict) -> None:
    """An uncompressed npz of ``arrays`` (name -> array, no pickles) that is a function of
    them alone: members in sorted order with a fixed zip timestamp, so equal arrays give
    byte-identical files (the local-against-Dask checks compare files)."""
    with zipfile.ZipFile(path, "w", zipfile.ZIP_STORED, allowZip64=True) as zf:
        for name in sorted(arrays):
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            with zf.open(info, "w", force_zip64=True) as member:
                np.lib.format.write_array(member, np.asanyarray(arrays[name]),
                                          allow_pickle=False)


@dataclass(frozen=True)
class SweepResult:
    """One sweep (see :mod:`grazing_control.studies.sweeps` for the meaning of each field).

    Points are ordered as ``np.ndindex(shape)``: grid axes in the order of ``names``
    (first slowest), then the starts.
    """

    names: tuple
    axes: tuple
    shape: tuple
    points: dict
    starts: np.ndarray
    pi2_deviation: np.ndarray
    reference: np.ndarray  # (n, 2): X** = (x**, v**) of each point
    impacts_per_period: np.ndarray
    period: np.ndarray
    errors: np.ndarray
    c1: np.ndarray
    c2: np.ndarray
    periods: int
    transient: int
    control_after: int  # -1: never
    base: dict = field(default_factory=dict)  # the OscillatorParams fields not gridded
    engine: str = ""
    delay: float = 0.0  # the actuation delay of the gains (0: the kick acts on Pi2)
    #: (n, 2) Lyapunov exponents per period of the kept samples' orbit, largest first
    #: (sweep(lyapunov=True); nan for a failed point), or None when not computed
    lyapunov: np.ndarray | None = None

    @property
    def pi2(self) -> np.ndarray:
        """(n, m, 2) physical Pi2 samples (x, v)."""
        return self.pi2_deviation + self.reference[:, None, :]

    @property
    def n_points(self) -> int:
        return int(self.period.shape[0])

    def to_npz(self, path) -> None:
        """Write every field to an uncompressed npz (readable without this package).

        The file is a function of the result alone (fixed member order and zip
        timestamps), so equal results give byte-identical files.
        """
        meta = {"format": _FORMAT, "names": list(self.names), "shape": list(self.shape),
                "periods": self.periods, "transient": self.transient,
                "control_after": self.control_after, "base": self.base, "engine": self.engine,
                "delay": self.delay}
        arrays = {f"axis_{n}": np.asarray(a) for n, a in zip(self.names, self.axes)}
        arrays.update({f"point_{n}": np.asarray(v) for n, v in self.points.items()})
        arrays.update(meta=np.array(json.dumps(meta, sort_keys=True)), starts=self.starts,
                      pi2=self.pi2, pi2_deviation=self.pi2_deviation, reference=self.reference,
                      impacts_per_period=self.impacts_per_period, period=self.period,
                      errors=self.errors, c1=self.c1, c2=self.c2)
        if self.lyapunov is not None:
            arrays["lyapunov"] = self.lyapunov
        write_npz(path, arrays)

    @classmethod
    def from_npz(cls, path) -> "SweepResult":
        """Read a file written by :meth:`to_npz`."""
        with np.load(path, allow_pickle=False) as f:
            meta = json.loads(str(f["meta"]))
            if meta.get("format") != _FORMAT:
                raise ValueError(f"{path}: not a sweep file (format {meta.get('format')!r})")
            names = tuple(meta["names"])
            return cls(
                names=names,
                axes=tuple(f[f"axis_{n}"] for n in names),
                shape=tuple(meta["shape"]),
                points={n: f[f"point_{n}"] for n in names},
                starts=f["starts"], pi2_deviation=f["pi2_deviation"], reference=f["reference"],
                impacts_per_period=f["impacts_per_period"], period=f["period"],
                errors=f["errors"], c1=f["c1"], c2=f["c2"], periods=int(meta["periods"]),
                transient=int(meta["transient"]), control_after=int(meta["control_after"]),
                base=dict(meta["base"]), engine=str(meta["engine"]),
                delay=float(meta.get("delay", 0.0)),
                lyapunov=f["lyapunov"] if "lyapunov" in f.files else None)

    def same_as(self, other: "SweepResult") -> bool:
        """Bitwise equality of every array and of the metadata (local vs Dask checks)."""
        arrays = ("starts", "pi2_deviation", "reference", "impacts_per_period", "period",
                  "errors", "c1", "c2")
        return (self.names == other.names and self.shape == other.shape
                and all(np.array_equal(a, b) for a, b in zip(self.axes, other.axes))
                and all(np.array_equal(self.points[n], other.points[n]) for n in self.names)
                and all(np.array_equal(getattr(self, a), getattr(other, a), equal_nan=a != "errors")
                        for a in arrays)
                and (self.lyapunov is None) == (other.lyapunov is None)
                and (self.lyapunov is None
                     or np.array_equal(self.lyapunov, other.lyapunov, equal_nan=True))
                and (self.periods, self.transient, self.control_after, self.base, self.delay)
                == (other.periods, other.transient, other.control_after, other.base, other.delay))
