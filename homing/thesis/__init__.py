"""The reproduction of Goldhoorn 2008's homing results, apart from the homing runtime.

The simulation of chapter 4 and appendix A (:mod:`~homing.thesis.simulation`), its four
experiments (:mod:`~homing.thesis.experiments`), toploc's controller for it
(:mod:`~homing.thesis.controller`), the thesis's own figures (:mod:`~homing.thesis.reference`,
``reference/``), the tables (:mod:`~homing.thesis.report`), why rows differ
(:mod:`~homing.thesis.explanations`), the statistics of homing on images (sections 5.6-5.7,
:mod:`~homing.thesis.evaluation`) and the plots. It builds on the runtime (:mod:`homing.alv`,
:mod:`homing.compass`, :mod:`homing.bearings`, :mod:`homing.home_directions`); the runtime
never imports it.
"""
