"""The report's sections, one module each; :mod:`locbench.report.build` assembles them in order."""
