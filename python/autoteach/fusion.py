"""Camera-LiDAR fusion layers: sparse non-homogeneous pooling (SHPL) and non-zero max-min pooling.

000_3b1454b2b2194811.txt ch. 7: the SHPL of Sec. 7.5 (eq. 7.4-7.9, Fig. 7.12) transforms
feature maps between the camera view and the LiDAR bird's eye view through the point cloud;
non-zero max-min pooling (Sec. 7.4, Figs. 7.5-7.6) down-samples sparse projected LiDAR maps.

Both are framework-free operators with explicit forward and backward passes on channels-last
``float32`` or ``float64`` arrays. C-contiguous inputs of those dtypes are read in place (no
copy) and results are returned without a copy, so a PyTorch or JAX custom op can wrap them
(``torch.from_numpy``/``np.asarray`` on either side). Results are bit-identical whatever the
number of threads.
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from autoteach import _core
from autoteach._convert import as_f64, as_float, as_int
from autoteach.errors import InvalidInputError

Direction = Literal["image_to_bev", "bev_to_image"]


def _features(x: ArrayLike, name: str) -> NDArray[Any]:
    arr = np.asarray(x)
    if arr.dtype.kind not in "iuf":
        raise InvalidInputError(f"{name} must hold real numbers, got dtype {arr.dtype}")
    if arr.dtype not in (np.float32, np.float64):
        arr = arr.astype(np.float64)
    return np.ascontiguousarray(arr)


class SparsePooling:
    """The SHPL operator of one point cloud (build once per frame, apply to every feature map).

    Build with :meth:`build`. ``image_grid = (rows, cols, stride)``: the image feature map has
    ``rows x cols`` cells of ``stride`` pixels (pixel ``(u, v)`` is cell ``(v // stride, u //
    stride)``). ``bev_grid = (x_min, y_min, cell, nx, ny)``: point ``(x, y, z)`` is BEV cell
    ``((x - x_min) // cell, (y - y_min) // cell)``. ``P`` is the 3x4 LiDAR-to-pixel projection
    (eq. 7.2). Points behind the camera or outside a grid are dropped and counted
    (:attr:`dropped`).
    """

    def __init__(self, inner: Any, image_grid: tuple[int, int, float], bev_grid: tuple[float, float, float, int, int]):
        """Wrap a compiled operator (use :meth:`build`)."""
        self._inner = inner
        self.image_grid = image_grid
        self.bev_grid = bev_grid

    @classmethod
    def build(
        cls,
        points: ArrayLike,
        P: ArrayLike,  # noqa: N803 - the seed's name of the projection matrix
        image_grid: tuple[int, int, float],
        bev_grid: tuple[float, float, float, int, int],
        neighbourhood: int = 1,
    ) -> SparsePooling:
        """Build the sparse kernel of eq. 7.4-7.8 (``neighbourhood``: odd window of source cells)."""
        ig = (
            as_int(image_grid[0], "image_grid[0] (rows)"),
            as_int(image_grid[1], "image_grid[1] (cols)"),
            as_float(image_grid[2], "image_grid[2] (stride)"),
        )
        bg = (
            as_float(bev_grid[0], "bev_grid[0] (x_min)"),
            as_float(bev_grid[1], "bev_grid[1] (y_min)"),
            as_float(bev_grid[2], "bev_grid[2] (cell)"),
            as_int(bev_grid[3], "bev_grid[3] (nx)"),
            as_int(bev_grid[4], "bev_grid[4] (ny)"),
        )
        inner = _core.FusionSparsePooling.build(
            as_f64(points, "points"), as_f64(P, "P"), ig, bg, as_int(neighbourhood, "neighbourhood")
        )
        return cls(inner, ig, bg)

    @property
    def kept(self) -> int:
        """Number of points in the kernel."""
        return int(self._inner.kept)

    @property
    def dropped(self) -> dict[str, int]:
        """Points dropped: behind the camera, outside the image grid, outside the BEV grid."""
        return dict(self._inner.dropped)

    def _shapes(self, direction: Direction) -> tuple[tuple[int, int], tuple[int, int]]:
        img = (self.image_grid[0], self.image_grid[1])
        bev = (self.bev_grid[3], self.bev_grid[4])
        if direction == "image_to_bev":
            return img, bev
        if direction == "bev_to_image":
            return bev, img
        raise InvalidInputError(f'direction must be "image_to_bev" or "bev_to_image", got {direction!r}')

    def _apply(self, x: ArrayLike, direction: Direction, backward: bool, name: str) -> NDArray[Any]:
        src, dst = self._shapes(direction)
        if backward:
            src, dst = dst, src
        arr = _features(x, name)
        as_map = arr.ndim == 3
        if as_map:
            if arr.shape[:2] != src:
                raise InvalidInputError(f"{name} must have shape ({src[0]}, {src[1]}, channels), got {arr.shape}")
            arr = arr.reshape(src[0] * src[1], arr.shape[2])
        out = (self._inner.backward if backward else self._inner.forward)(direction, arr)
        return out.reshape(dst[0], dst[1], -1) if as_map else out

    def forward(self, features: ArrayLike, direction: Direction = "image_to_bev") -> NDArray[Any]:
        """Pool ``features`` (``(cells, C)`` or a ``(rows, cols, C)`` map of the source grid)."""
        return self._apply(features, direction, False, "features")

    def backward(self, grad: ArrayLike, direction: Direction = "image_to_bev") -> NDArray[Any]:
        """Gradient with respect to the input of :meth:`forward`, given ``grad`` of its output."""
        return self._apply(grad, direction, True, "grad")

    def csr(
        self, direction: Direction = "image_to_bev"
    ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64], tuple[int, int]]:
        """The kernel as ``(indptr, indices, data, shape)``.

        ``scipy.sparse.csr_matrix((data, indices, indptr), shape)`` rebuilds it.
        """
        self._shapes(direction)
        return self._inner.csr(direction)

    def dense(self, direction: Direction = "image_to_bev") -> NDArray[np.float64]:
        """The kernel as a dense ``(output cells, input cells)`` matrix (small problems only)."""
        self._shapes(direction)
        return self._inner.dense(direction)


def maxmin_pool(x: ArrayLike) -> NDArray[Any]:
    """Non-zero max-min pooling of ``x (h, w, c)`` to ``(ceil(h/2), ceil(w/2), 2c)``.

    Channel ``k`` holds the maximum and ``c + k`` the minimum of the non-zero values of each 2x2
    window (0 where a window has none).
    """
    return _core.fusion_maxmin_pool(_features(x, "x"))


def maxmin_pool_backward(x: ArrayLike, grad_out: ArrayLike) -> NDArray[Any]:
    """Gradient of :func:`maxmin_pool` with respect to ``x`` given ``grad_out``."""
    a = _features(x, "x")
    return _core.fusion_maxmin_pool_backward(a, _features(grad_out, "grad_out").astype(a.dtype, copy=False))


__all__ = ["SparsePooling", "maxmin_pool", "maxmin_pool_backward"]
