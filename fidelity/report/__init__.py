"""Reports: JSON for machines, HTML for people, JUnit XML for CI, terminal summaries."""
