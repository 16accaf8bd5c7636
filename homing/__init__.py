"""ALV visual homing: landmark vectors, home vectors, visual compasses, the thesis simulation."""
