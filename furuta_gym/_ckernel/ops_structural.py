"""The translation of structural primitives (reshape, slice, broadcast, transpose, pad, ...):
aliases, or copies by index runs that numpy works out from the operation itself."""

from __future__ import annotations

import numpy as np

from .c_writer import CWriter
from .errors import CKernelTranslationError


class StructuralOps(CWriter):
    """Primitives that move elements without computing: aliases and index-run copies."""

    def op_reshape(self, ins, avals, dimensions=None, **_):
        if dimensions is not None:
            raise CKernelTranslationError("reshape with 'dimensions' has no C translation")
        return [self.alias(ins[0], avals[0])]

    def op_squeeze(self, ins, avals, **_):
        return [self.alias(ins[0], avals[0])]

    def op_expand_dims(self, ins, avals, **_):
        return [self.alias(ins[0], avals[0])]

    def _gather_by_numpy(self, ins, aval, indexer, fill=None):
        """Copy ``out = indexer(arange inputs)``: numpy applies the structural op to index arrays
        (input k's flat index + its offset), which gives every output's source."""
        sizes = [max(x.size, 1) for x in ins]
        offsets = np.concatenate([[0], np.cumsum(sizes)])
        labelled = [np.arange(offsets[k], offsets[k + 1]).reshape(x.shape) for k, x in enumerate(ins)]
        flat = np.asarray(indexer(*labelled)).ravel()
        sources = np.searchsorted(offsets, flat, side="right") - 1
        sources = np.where(flat < 0, -1, sources)
        indices = np.where(flat < 0, 0, flat - offsets[np.clip(sources, 0, None)])
        out = self.fresh(aval)
        self.copy_runs(out, ins, sources, indices, fill)
        return out

    def op_slice(self, ins, avals, start_indices, limit_indices, strides=None):
        strides = strides or (1,) * len(start_indices)
        sl = tuple(slice(a, b, s) for a, b, s in zip(start_indices, limit_indices, strides, strict=True))
        return [self._gather_by_numpy(ins, avals[0], lambda a: a[sl])]

    def op_broadcast_in_dim(self, ins, avals, shape, broadcast_dimensions, **_):
        def bcast(a):
            placed = [1] * len(shape)  # operand dim i sits at output dim broadcast_dimensions[i]
            for i, d in enumerate(broadcast_dimensions):
                placed[d] = a.shape[i]
            return np.broadcast_to(a.reshape(placed), shape)

        return [self._gather_by_numpy(ins[:1], avals[0], bcast)]

    def op_transpose(self, ins, avals, permutation):
        return [self._gather_by_numpy(ins, avals[0], lambda a: np.transpose(a, permutation))]

    def op_rev(self, ins, avals, dimensions):
        return [self._gather_by_numpy(ins, avals[0], lambda a: np.flip(a, dimensions))]

    def op_concatenate(self, ins, avals, dimension):
        return [self._gather_by_numpy(ins, avals[0], lambda *a: np.concatenate(a, axis=dimension))]

    def op_stack(self, ins, avals, axis):
        return [self._gather_by_numpy(ins, avals[0], lambda *a: np.stack(a, axis=axis))]

    def op_unstack(self, ins, avals, axis):
        return [
            self._gather_by_numpy(ins, aval, lambda a, k=k: np.take(a, k, axis=axis)) for k, aval in enumerate(avals)
        ]

    def op_split(self, ins, avals, sizes, axis):
        bounds = np.cumsum((0,) + tuple(sizes))
        return [
            self._gather_by_numpy(ins, aval, lambda a, k=k: np.take(a, np.arange(bounds[k], bounds[k + 1]), axis=axis))
            for k, aval in enumerate(avals)
        ]

    def op_pad(self, ins, avals, padding_config):
        operand, fill = ins

        def pad(a):
            if any(int(i) < 0 for _, _, i in padding_config):
                raise CKernelTranslationError("pad with negative interior padding has no C translation")
            shape = list(a.shape)
            for d, (lo, hi, interior) in enumerate(padding_config):
                lo, hi, interior = int(lo), int(hi), int(interior)
                n = shape[d]
                dilated = n + max(n - 1, 0) * interior
                full = np.full(a.shape[:d] + (dilated,) + a.shape[d + 1 :], -1, dtype=np.int64)
                idx = [slice(None)] * a.ndim
                idx[d] = slice(0, dilated, interior + 1)
                full[tuple(idx)] = a
                # negative lo/hi crop
                pads = [(0, 0)] * a.ndim
                pads[d] = (max(lo, 0), max(hi, 0))
                full = np.pad(full, pads, constant_values=-1)
                crop = [slice(None)] * a.ndim
                crop[d] = slice(max(-lo, 0), full.shape[d] - max(-hi, 0))
                a = full[tuple(crop)]
                shape[d] = a.shape[d]
            return a

        return [self._gather_by_numpy([operand], avals[0], pad, fill=fill)]
