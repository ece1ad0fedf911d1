"""Scan plans: what to measure, checked against a rig and timed before anything moves.

Import each name from the module that holds it:

``models``
    The plan kinds (uniform, adaptive, calibration), their settings, :class:`PlanError`,
    ``parse_plan``.
``validation``
    Checks of a plan against a :class:`gonio.rigdescription.RigDescription`; its pairs, lights
    and first-round angles.
``checked``
    :class:`~gonio.plans.checked.CheckedPlan`: a plan checked once, with what the check found,
    handed from the submission to the worker, the engine and the finishing.
``route``
    Stage positions visiting a set of specimen angles in one direction with least travel.
``timing``
    Move times along a route (engine and driver backlash legs), and adaptive time bounds.
``adaptive``
    Where an adaptive plan adds angles next by V&F's rule (leave-one-out periodic PCHIP).
``arc``
    The arc from the data (``arc = "auto"``): the first round's opposite angles, the twofold
    symmetry test that chooses half or a full turn, the dry run's bounds of both outcomes.
``rounds``
    The rounds each plan kind owns (one, adaptive refinement, or the arc test first) and the
    ``Refiner`` protocol of the posterior rule.
``faults``
    ``Suspender``: a plan's fault policy applied (wait and retry, or fail, and why).
``dryrun``
    A plan's first-round route and duration estimate, without hardware.
"""
