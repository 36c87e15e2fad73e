"""The experiment engine and what every protocol shares: runs with fingerprints and stamps, one
executor with resume (engine), success counts and their statistics (results, stats), report tables and
charts."""
