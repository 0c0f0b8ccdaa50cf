"""The camera properties measured on a located chart, one module each: colour (ΔE and
the chart's statistics), the pixel measurement of an image, its uncertainty and blind spots."""
