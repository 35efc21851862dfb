"""What every command guarantees about files, resources and stops, each written once:

- `exits`: the exit codes and the error types that carry them;
- `reading`: the one reader of users' files (OS, decoding and parse errors -> exit 2 or 4, naming
  the file and line);
- `writing`: atomic, synced writes; no partial file on a full disk (exit 4); stale temporaries of
  killed processes removed;
- `outputs`: an output never aliases an input, never replaces a read-only, special or foreign
  file; output folders hold only what granel wrote there;
- `owners`: who wrote a file (granel's mark, a folder's stamp), who holds a lock (host, pid and
  the process's start time);
- `resources`: memory and disk estimated before they are spent;
- `fingerprints`: the contents of every input a resumable command reads;
- `signals`: Ctrl-C and SIGTERM end any command with one line (exit 130 / 143);
- `jit`: numba's cache of the compiled kernels, keyed by all their sources and verified.

May import: nothing of granel but its version."""
