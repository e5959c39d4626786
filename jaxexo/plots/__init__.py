"""Figures and animations of swings and walks (matplotlib, imported on first use): ``plot`` (a
swing's figure, a walk's figure) and ``animate`` (a swing or a walk as a GIF). Nothing on the
generator's path imports them."""
