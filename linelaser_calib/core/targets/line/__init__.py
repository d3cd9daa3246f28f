"""The straight-line target: a seam or edge seen from many poses, no point taught."""
