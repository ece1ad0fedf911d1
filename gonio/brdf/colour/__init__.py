"""Colour from a BRDF: CIE XYZ and CIELAB at instrument geometries, flop index, CIEDE2000.

Every colorimetric number is computed by ``colour-science`` (the ``colour`` package): the CIE
colour-matching functions and illuminants, ASTM E308 weighting, the XYZ to CIELAB transform and
CIEDE2000. gonio's own part is only what the library cannot know: how a sensor's channels
become a spectrum or XYZ (:mod:`~gonio.brdf.colour.spectral`, :mod:`~gonio.brdf.colour.chart`),
which directions an instrument looks from (:mod:`~gonio.brdf.colour.instruments`), and reading
those directions out of a reconstructed table (:mod:`~gonio.brdf.colour.report`).

==================  ===========================================================================
``conditions``      illuminant and observer (D65, CIE 1964 10 degree by default), spectral
                    reflectance to XYZ (ASTM E308), XYZ to CIELAB, CIEDE2000
``spectral``        spectral sensor bands (centre and width, or a response table) and the
                    reflectance spectrum behind a set of band readings
``chart``           colour calibration of RGB sensors from a chart of known reflectances
``instruments``     the aspecular geometries of multi-angle spectrophotometers
``report``          the colour numbers of a reconstructed table at those geometries, flop
                    index, colour differences between two reports
``exportspace``     linear sRGB from XYZ, for exports that state their colour space
``errors``          :class:`ColourError` (importable without loading colour-science)
==================  ===========================================================================
"""
