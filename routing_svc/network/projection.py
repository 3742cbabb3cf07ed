"""Geographic projection of a SUMO network: (lon, lat) <-> network (x, y).

SUMO stores the projection of a network in its ``<location>`` element: a PROJ
string (``projParameter``) and an offset (``netOffset``) that netconvert added
to the projected coordinates. Network coordinates are
``x = E + offset_x, y = N + offset_y`` where ``(E, N)`` is the projected point.

Networks imported from OpenStreetMap use UTM (``+proj=utm +zone=Z [+south]``
on the WGS84 ellipsoid), which this module implements itself with Krüger's
series to sixth order in the third flattening (C. F. F. Karney, "Transverse
Mercator with an accuracy of a few nanometers", J. Geodesy 85, 2011), so no
PROJ installation is needed. Other projections are recorded but not
converted: :meth:`GeoProjection.to_xy` raises
:class:`~routing_svc.errors.InvalidInput` for them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from numba import njit

from routing_svc.errors import InvalidInput
from routing_svc.types import FloatArray

__all__ = ["GeoProjection"]


_A = 6378137.0
_F = 1.0 / 298.257223563
_K0 = 0.9996
_FALSE_EASTING = 500000.0
_FALSE_NORTHING_SOUTH = 10000000.0
_ELLIPSOIDS = frozenset({"WGS84", "GRS80"})

_N = _F / (2.0 - _F)
_E = math.sqrt(_F * (2.0 - _F))
_RECTIFYING_RADIUS = _A / (1.0 + _N) * (1.0 + _N**2 / 4.0 + _N**4 / 64.0 + _N**6 / 256.0)


def _series(coefficients: list[list[float]]) -> FloatArray:
    """Evaluate polynomials in the third flattening n (lowest order first, from n^1)."""
    return np.array([sum(c * _N ** (k + 1) for k, c in enumerate(row)) for row in coefficients])


_ALPHA = _series(
    [
        [1 / 2, -2 / 3, 5 / 16, 41 / 180, -127 / 288, 7891 / 37800],
        [0, 13 / 48, -3 / 5, 557 / 1440, 281 / 630, -1983433 / 1935360],
        [0, 0, 61 / 240, -103 / 140, 15061 / 26880, 167603 / 181440],
        [0, 0, 0, 49561 / 161280, -179 / 168, 6601661 / 7257600],
        [0, 0, 0, 0, 34729 / 80640, -3418889 / 1995840],
        [0, 0, 0, 0, 0, 212378941 / 319334400],
    ]
)
_BETA = _series(
    [
        [1 / 2, -2 / 3, 37 / 96, -1 / 360, -81 / 512, 96199 / 604800],
        [0, 1 / 48, 1 / 15, -437 / 1440, 46 / 105, -1118711 / 3870720],
        [0, 0, 17 / 480, -37 / 840, -209 / 4480, 5569 / 90720],
        [0, 0, 0, 4397 / 161280, -11 / 504, -830251 / 7257600],
        [0, 0, 0, 0, 4583 / 161280, -108847 / 3991680],
        [0, 0, 0, 0, 0, 20648693 / 638668800],
    ]
)
_ORDERS = 2.0 * np.arange(1, 7, dtype=np.float64)


@dataclass(frozen=True, slots=True)
class GeoProjection:
    """The projection of a network, as stored in its ``<location>`` element.

    Attributes
    ----------
    proj : str
        The PROJ string of the network (``projParameter``).
    offset_x, offset_y : float
        ``netOffset``: added to projected coordinates to give network ones.
    utm_zone : int
        UTM zone (1..60), or 0 when the projection is not a WGS84 UTM one.
    south : bool
        Whether the UTM zone is on the southern hemisphere.
    """

    proj: str
    offset_x: float
    offset_y: float
    utm_zone: int
    south: bool

    @classmethod
    def parse(cls, proj: str, offset: tuple[float, float]) -> GeoProjection:
        """Build a projection from SUMO's ``projParameter`` and ``netOffset``.

        Parameters
        ----------
        proj : str
            The PROJ string, e.g. ``"+proj=utm +zone=33 +ellps=WGS84 +units=m"``.
        offset : tuple[float, float]
            The network offset.
        """
        options: dict[str, str] = {}
        for token in proj.split():
            key, _, value = token.lstrip("+").partition("=")
            options[key] = value
        zone = 0
        ellipsoid = options.get("ellps", options.get("datum", "WGS84"))
        if (
            options.get("proj") == "utm"
            and ellipsoid in _ELLIPSOIDS
            and options.get("zone", "").isdigit()
        ):
            zone = int(options["zone"])
            if not 1 <= zone <= 60 or options.get("units", "m") != "m":
                zone = 0
        return cls(
            proj=proj,
            offset_x=float(offset[0]),
            offset_y=float(offset[1]),
            utm_zone=zone,
            south="south" in options,
        )

    @property
    def supported(self) -> bool:
        """Whether this module can convert coordinates for this projection."""
        return self.utm_zone > 0

    def _require_supported(self) -> None:
        if not self.supported:
            raise InvalidInput(
                f"coordinate conversion for projection {self.proj!r} is not supported"
            )

    @property
    def _central_meridian(self) -> float:
        return math.radians(6.0 * self.utm_zone - 183.0)

    def to_xy(self, lon: npt.ArrayLike, lat: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Network coordinates of geographic points (degrees, WGS84).

        Parameters
        ----------
        lon, lat : array_like
            Longitudes and latitudes in degrees.

        Returns
        -------
        x, y : FloatArray
            Network coordinates (metres).
        """
        self._require_supported()
        phi = np.radians(np.asarray(lat, dtype=np.float64))
        lam = np.radians(np.asarray(lon, dtype=np.float64)) - self._central_meridian
        lam = (lam + math.pi) % (2.0 * math.pi) - math.pi
        sin_phi = np.sin(phi)
        tau = np.tan(phi)
        sigma = np.sinh(_E * np.arctanh(_E * sin_phi))
        t = tau * np.sqrt(1.0 + sigma**2) - sigma * np.sqrt(1.0 + tau**2)
        xi_p = np.arctan2(t, np.cos(lam))
        eta_p = np.arcsinh(np.sin(lam) / np.sqrt(t**2 + np.cos(lam) ** 2))
        angles = _ORDERS[:, None] * xi_p.reshape(1, -1)
        hyper = _ORDERS[:, None] * eta_p.reshape(1, -1)
        xi = xi_p + (_ALPHA[:, None] * np.sin(angles) * np.cosh(hyper)).sum(axis=0).reshape(
            xi_p.shape
        )
        eta = eta_p + (_ALPHA[:, None] * np.cos(angles) * np.sinh(hyper)).sum(axis=0).reshape(
            eta_p.shape
        )
        easting = _FALSE_EASTING + _K0 * _RECTIFYING_RADIUS * eta
        northing = _K0 * _RECTIFYING_RADIUS * xi + (_FALSE_NORTHING_SOUTH if self.south else 0.0)
        return easting + self.offset_x, northing + self.offset_y

    def to_lonlat(self, x: npt.ArrayLike, y: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Geographic coordinates (degrees, WGS84) of network points.

        Parameters
        ----------
        x, y : array_like
            Network coordinates (metres).

        Returns
        -------
        lon, lat : FloatArray
            Longitudes and latitudes in degrees.
        """
        self._require_supported()
        easting = np.asarray(x, dtype=np.float64) - self.offset_x
        northing = np.asarray(y, dtype=np.float64) - self.offset_y
        if self.south:
            northing = northing - _FALSE_NORTHING_SOUTH
        shape = np.broadcast_shapes(easting.shape, northing.shape)
        lon, lat = _inverse_points(
            np.broadcast_to(easting, shape).ravel(),
            np.broadcast_to(northing, shape).ravel(),
            self._central_meridian,
        )
        return lon.reshape(shape), lat.reshape(shape)

    def point_to_lonlat(self, x: float, y: float) -> tuple[float, float]:
        """:meth:`to_lonlat` of one point, without arrays (the same arithmetic)."""
        self._require_supported()
        northing = y - self.offset_y
        if self.south:
            northing -= _FALSE_NORTHING_SOUTH
        return _inverse_point(x - self.offset_x, northing, self._central_meridian)


@njit(cache=True)
def _inverse_point(easting: float, northing: float, central_meridian: float) -> tuple[float, float]:
    """Krüger's inverse series (Karney 2011, eqs. 11-15 and 19-21) for one point."""
    xi = northing / (_K0 * _RECTIFYING_RADIUS)
    eta = (easting - _FALSE_EASTING) / (_K0 * _RECTIFYING_RADIUS)
    xi_p = xi
    eta_p = eta
    for j in range(6):
        angle = _ORDERS[j] * xi
        hyper = _ORDERS[j] * eta
        xi_p -= _BETA[j] * math.sin(angle) * math.cosh(hyper)
        eta_p -= _BETA[j] * math.cos(angle) * math.sinh(hyper)
    tau_p = math.sin(xi_p) / math.sqrt(math.sinh(eta_p) ** 2 + math.cos(xi_p) ** 2)
    lam = math.atan2(math.sinh(eta_p), math.cos(xi_p))
    tau = tau_p
    for _ in range(5):
        sigma = math.sinh(_E * math.atanh(_E * tau / math.sqrt(1.0 + tau**2)))
        tau_i = tau * math.sqrt(1.0 + sigma**2) - sigma * math.sqrt(1.0 + tau**2)
        tau = tau + (tau_p - tau_i) / math.sqrt(1.0 + tau_i**2) * (
            (1.0 + (1.0 - _E**2) * tau**2) / ((1.0 - _E**2) * math.sqrt(1.0 + tau**2))
        )
    lon = math.degrees(lam + central_meridian)
    return (lon + 180.0) % 360.0 - 180.0, math.degrees(math.atan(tau))


@njit(cache=True)
def _inverse_points(
    easting: FloatArray, northing: FloatArray, central_meridian: float
) -> tuple[FloatArray, FloatArray]:
    """:func:`_inverse_point` of every point."""
    lon = np.empty(easting.size)
    lat = np.empty(easting.size)
    for i in range(easting.size):
        lon[i], lat[i] = _inverse_point(easting[i], northing[i], central_meridian)
    return lon, lat
