"""The stages of a study, one module each: pack (free fall into the cylinder), trim (cut at
h0 = a r0), collapse (the wall removed, run to rest), analyse (final height, run-out, front) and
collect (the analyses of a study in one dataset)."""
