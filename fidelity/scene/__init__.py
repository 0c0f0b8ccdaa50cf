"""The chart scene for simulators: one model (:mod:`fidelity.scene.model`) and a small writer per
format (glTF 2.0 binary, OpenUSD, Mitsuba 3 XML; :mod:`fidelity.scene.export`)."""
