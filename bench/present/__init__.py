"""Presentation helpers shared by the report and the claims: document formatting, the palette, ranking marks,
metric display records and the experiments registry."""
