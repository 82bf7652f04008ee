"""16-bit samples standing in for an utterance's float32 audio: in memory (:class:`Pcm`) or left on disk in a
``.npy`` file (:class:`PcmFile`), read as float32 a stretch at a time.

:class:`Pcm` holds a synthesis's samples at half the memory of their float32 array; :class:`PcmFile` stands in for an utterance's ``audio`` array (length, ``dtype``, slicing and indexing give
what the array would), so that a long narration whose samples are in the speech cache is never held whole:
whoever mixes it reads the stretch it needs. ``np.asarray`` on it reads it whole.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # numpy is imported where samples are read: holding a file's place does without it
    import numpy as np

__all__ = ["Pcm16", "Pcm", "PcmFile", "pcm_to_float"]

#: 16-bit samples converted at a time when a file is read whole.
BLOCK = 1 << 20


def pcm_to_float(pcm: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """16-bit samples as float32 in [-1, 1) (divided by 32768, in float32)."""
    import numpy as np

    return np.divide(pcm, np.float32(32768.0), out=out, dtype=np.float32)


class Pcm16:
    """16-bit mono samples standing in for their float32 array (divided by 32768): length, ``dtype``,
    slicing and indexing give what the array would, read a stretch at a time by :meth:`read`;
    ``np.asarray`` gives the array whole."""

    ndim = 1
    length = 0
    #: bytes of memory the samples hold (those read from a file when asked for hold none)
    held_bytes = 0

    def read(self, first: int, last: int) -> np.ndarray:
        """Samples ``first .. last - 1`` (clipped to the samples) as float32."""
        raise NotImplementedError

    @property
    def dtype(self):
        """float32, the samples' type as read."""
        import numpy as np

        return np.dtype(np.float32)

    @property
    def shape(self) -> tuple[int]:
        return (self.length,)

    @property
    def size(self) -> int:
        return self.length

    def __len__(self) -> int:
        return self.length

    def astype(self, dtype, copy: bool = True) -> np.ndarray:
        """The samples whole, as an array of ``dtype``."""
        import numpy as np

        return np.asarray(self, dtype=dtype)

    def tobytes(self) -> bytes:
        """The float32 samples' bytes, as the array's ``tobytes``."""
        import numpy as np

        return np.asarray(self).tobytes()

    def copy(self) -> np.ndarray:
        """The samples whole, as a float32 array."""
        import numpy as np

        return np.asarray(self)

    def __getitem__(self, key):
        import numpy as np

        if isinstance(key, slice):
            first, last, step = key.indices(self.length)
            if step == 1:
                return self.read(first, last)
            return self.read(0, self.length)[key]
        if isinstance(key, (int, np.integer)):
            k = int(key) + (self.length if key < 0 else 0)
            if not 0 <= k < self.length:
                raise IndexError(f"sample {key} of {self.length}")
            return self.read(k, k + 1)[0]
        index = np.asarray(key)
        if index.dtype == bool:
            index = np.flatnonzero(index)
        if index.size == 0:
            return np.empty(index.shape, np.float32)
        index = np.where(index < 0, index + self.length, index)
        lo, hi = int(index.min()), int(index.max()) + 1
        if lo < 0 or hi > self.length:
            raise IndexError(f"samples {lo}..{hi - 1} of {self.length}")
        return self.read(lo, hi)[index - lo]

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        import numpy as np

        out = np.empty(self.length, np.float32)
        for a in range(0, self.length, BLOCK):
            out[a:a + BLOCK] = self.read(a, a + BLOCK)
        return out if dtype is None else out.astype(dtype, copy=False)


class Pcm(Pcm16):
    """The float32 samples of 16-bit samples held in memory (``pcm``, int16): half the memory of the float32
    array they stand for, converted a stretch at a time when read."""

    def __init__(self, pcm: np.ndarray) -> None:
        import numpy as np

        if pcm.dtype != np.int16 or pcm.ndim != 1:
            raise ValueError("not 16-bit mono samples")
        self.pcm = pcm
        self.length = int(len(pcm))
        self.held_bytes = int(pcm.nbytes)

    def read(self, first: int, last: int) -> np.ndarray:
        first, last = max(0, int(first)), min(self.length, int(last))
        return pcm_to_float(self.pcm[first:max(first, last)])


class PcmFile(Pcm16):
    """The float32 samples of a ``.npy`` file of 16-bit mono samples, read from the file when asked for.

    Raises ValueError if the file holds no 16-bit mono samples or is cut short.
    """

    def __init__(self, path: str | Path) -> None:
        import numpy as np

        self.path = Path(path)
        mapped = np.load(self.path, mmap_mode="r")  # the header only: no sample is read here
        if mapped.dtype != np.dtype("<i2") or mapped.ndim != 1:
            raise ValueError(f"{self.path}: not 16-bit mono samples")
        self.offset = int(mapped.offset)
        self.length = int(mapped.shape[0])
        del mapped
        # held open: a cache entry written anew (under another name, then renamed) leaves these samples as
        # they were
        self._file = open(self.path, "rb")

    def read(self, first: int, last: int) -> np.ndarray:
        """Samples ``first .. last - 1`` (clipped to the file) as float32."""
        import numpy as np

        first, last = max(0, int(first)), min(self.length, int(last))
        count = max(0, last - first)
        data = os.pread(self._file.fileno(), 2 * count, self.offset + 2 * first)  # no shared file position
        if len(data) != 2 * count:
            raise ValueError(f"{self.path}: cut short")
        return pcm_to_float(np.frombuffer(data, dtype="<i2"))

    def close(self) -> None:
        """Close the file (the samples can no longer be read)."""
        self._file.close()
