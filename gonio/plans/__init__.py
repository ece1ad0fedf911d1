"""Scan plans: what to measure, checked against a rig and timed before anything moves.

Import each name from the module that holds it:

``models``
    The plan kinds (uniform, adaptive, calibration), their settings, :class:`PlanError`,
    ``parse_plan``.
``validation``
    Checks of a plan against a :class:`gonio.rigdescription.RigDescription`; its pairs, lights
    and first-round angles.
``route``
    Stage positions visiting a set of specimen angles in one direction with least travel.
``timing``
    Move times along a route (engine and driver backlash legs), and adaptive time bounds.
``adaptive``
    Where an adaptive plan adds angles next (leave-one-out periodic PCHIP).
``dryrun``
    A plan's first-round route and duration estimate, without hardware.
"""
