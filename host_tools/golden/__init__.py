"""The float golden model, one module per stage: run log -> proxy -> rate -> regressors -> model -> combiner -> compensated output, flags and input checks."""
