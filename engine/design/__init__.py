"""Member design: the section catalogues, the EN 1993 checks, section sizing, the verdicts and the
load test."""
