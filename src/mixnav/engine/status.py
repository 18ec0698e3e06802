"""Status codes of a measurement update (shared by the engine and the compiled kernels)."""

#: applied
OK = 0
#: innovation covariance not positive definite: epoch rejected (counted)
S_NOT_POSITIVE_DEFINITE = 1
#: innovation beyond the absurd-innovation gate: epoch rejected (counted)
ABSURD = 2
#: the posterior has a non-finite value: nothing applied, the engine raises
NON_FINITE = 3
#: applied, but a variance of the posterior is not positive: the estimator repairs it (counted)
NEEDS_REPAIR = 4
