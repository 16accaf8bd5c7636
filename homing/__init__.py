"""ALV visual homing: bearing conventions, landmark vectors and home vectors, visual compasses
and home directions from two views (the runtime); the thesis reproduction is
:mod:`homing.thesis`, which the runtime never imports."""
