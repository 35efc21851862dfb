"""What every command guarantees about files, resources and stops, each written once: `exits`
(the exit codes and their errors), `reading` (users' files), `writing` (atomic writes), `outputs`
(the output rules), `owners` (who wrote a file, who holds a lock), `resources` (memory and disk),
`fingerprints` (inputs' contents), `signals` (Ctrl-C and SIGTERM) and `jit` (numba's cache of the
compiled kernels). docs/architecture.md ("`guard/`") says what each one guarantees.

May import: nothing of granel but its version."""
