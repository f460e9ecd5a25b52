"""Two raw sweeps: the ground, the ego motion, ICP, islands, slow movers, deskew."""
