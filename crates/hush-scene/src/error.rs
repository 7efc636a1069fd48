use std::fmt;
use std::path::{Path, PathBuf};

/// A scene that cannot be loaded: names the file, the line where known, and what to do.
#[derive(Debug)]
pub struct SceneError {
    pub path: PathBuf,
    pub line: Option<u32>,
    pub message: String,
}

impl SceneError {
    pub(crate) fn new(path: &Path, line: Option<u32>, message: impl Into<String>) -> Self {
        SceneError { path: path.to_path_buf(), line, message: message.into() }
    }
}

impl fmt::Display for SceneError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.line {
            Some(line) => write!(f, "{}:{}: {}", self.path.display(), line, self.message),
            None => write!(f, "{}: {}", self.path.display(), self.message),
        }
    }
}

impl std::error::Error for SceneError {}
