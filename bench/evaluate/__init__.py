"""Evaluation: the aligned view of an estimate against the truth, the metrics, the proper scores, lost and
recovery, the posterior Cramer-Rao bound, aggregation over seeds and the significance tests.

Pure functions of stored arrays: this layer runs no filter and writes no file.
"""
