//! What a long task reports while it runs: the resumable evaluation and the runner of many pairs tell
//! one [`Progress`], which the `rgm` command shows as a bar and the Python package ignores.

/// A long task's report.
pub trait Progress: Sync {
    /// Computing starts: `done` of the `total` items were read back from a file. Not called
    /// when none is missing.
    fn start(&self, total: usize, done: usize);
    /// One more item is finished (called from the workers).
    fn advance(&self);
    /// Computing ends; `complete` is false when it stopped before the last item.
    fn finish(&self, complete: bool);
    /// Something the user should read (a file's warning, a repeated pair), said where the
    /// report is shown; dropped by default.
    fn note(&self, _message: &str) {}
}

/// No report.
impl Progress for () {
    fn start(&self, _: usize, _: usize) {}
    fn advance(&self) {}
    fn finish(&self, _: bool) {}
}
