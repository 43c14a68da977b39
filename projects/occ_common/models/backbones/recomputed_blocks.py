"""The ``with_cp`` switch of the recomputed mmdet backbones."""


class RecomputedBlocks:
    """Mixin for an mmdet backbone whose blocks are recomputed by
    :func:`~projects.occ_common.models.layers.checkpointing.checkpoint_if_grad`
    in the subclass's ``forward`` instead of by mmdet's own ``with_cp``.

    The mmdet backbone is built with ``with_cp=False`` (its blocks then
    never checkpoint themselves); ``self.with_cp`` keeps the configured
    value for ``forward``.

    Args:
        *args: The mmdet backbone's positional arguments.
        with_cp (bool): Recompute the blocks in the backward. Defaults to
            False.
        **kwargs: The mmdet backbone's other keyword arguments.
    """

    def __init__(self, *args, with_cp: bool = False, **kwargs) -> None:
        super().__init__(*args, with_cp=False, **kwargs)
        self.with_cp = with_cp
