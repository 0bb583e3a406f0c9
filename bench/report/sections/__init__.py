"""The report's sections, one module each, each a function of :class:`locbench.report.context.Report`;
:mod:`locbench.report.build` assembles them in order (no section imports it)."""
