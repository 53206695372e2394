"""Views of arrays without reference counts, for compiled kernels (numba) whose helpers receive arrays.

numba counts references to an array each time a helper it inlines receives one, or a row of it is taken as a view
(an atomic increment and decrement each), and its pass that prunes the pairs misses many: that was about half of a
render's time in the demo ray caster's per-ray loops, 80 % of the adaptive sampler's judging of leaves, a tenth to a
sixth of the splat compositor's CPU (``docs/performance-log.md``). A kernel passes views of its own arguments to its
helpers instead, which are alive for the whole call. Used by the exact demo renderer, the adaptive sampler and the
splat compositor; the fitted field's ray kernel and the training kernels measured no faster with them (the pruning
pass keeps their loops free of counts).
"""

from __future__ import annotations

from numba.extending import intrinsic
from numba.np.arrayobj import populate_array

__all__ = ["borrowed"]


@intrinsic
def borrowed(typingctx, array):
    """A view of ``array`` without a reference count, valid while the caller holds ``array``.

    Never borrow an array the kernel allocates itself: numba frees it after its last named use, and the view
    would outlive it."""
    def codegen(context, builder, signature, args):
        source = context.make_array(signature.args[0])(context, builder, value=args[0])
        view = context.make_array(signature.return_type)(context, builder)
        populate_array(view, data=source.data, shape=source.shape, strides=source.strides,
                       itemsize=source.itemsize, meminfo=None)
        return view._getvalue()

    return array(array), codegen
