"""Where to put the light/sensor pairs.

=================  ============================================================================
``constraints``    what a rig allows (elevation, separation, device distance, exclusions) and
                   the grid cells that leaves
``conditioning``   the objective: condition number of basis rows, its fast rank-one update
``search``         the V&F neighbourhood search over basis rows
``mounting``       placement during the search, so every visited design can be mounted
``placement``      collision-free lab placement of a finished design
``pairs``          ``design_pairs`` (n independent pairs), ``geometry_design``, ``PairDesign``
``product``        ``design_product_rig`` (every light with every sensor)
``presets``        industrial multi-angle geometries (V&F Table 1)
``roughness``      the smallest roughness a design resolves
``heldout``        expected error on materials held out of the basis; choosing among designs
``errors``         ``DesignError``, ``FeasibilityError``
=================  ============================================================================
"""
