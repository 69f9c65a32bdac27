//! Writing output files without ever destroying one or leaving half of one behind.
//!
//! - A regular file (or a new one) is written to a temporary file beside it and renamed into
//!   place, so an interrupted or failed write never leaves a truncated file under the final name.
//! - A symbolic link is followed: the file it points to is replaced and the link stays.
//! - A special file (a device such as `/dev/null`, a FIFO, a terminal, `/dev/stdout`) is written
//!   through once the content is complete, never replaced by a regular file.
//! - A folder is refused.
//! - While an [`OutputBatch`] is open on a thread, the files that thread writes are all staged
//!   first and moved into place together by [`OutputBatch::commit`]: when one output cannot be
//!   written, none of the others has replaced its old file.
//! - Every temporary file is registered until it is renamed or removed, so that a signal
//!   handler can remove them ([`remove_temporaries`]).

use crate::error::{Error, Result};
use std::cell::RefCell;
use std::fs::OpenOptions;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

/// The longest file name most file systems take (NAME_MAX), in bytes.
pub const MAX_FILE_NAME_BYTES: usize = 255;

/// How many symbolic links a path may pass through (Linux's own limit).
const MAX_LINKS: usize = 40;

/// Where an output's bytes go.
#[derive(Clone, Debug, PartialEq, Eq)]
enum Target {
    /// A regular file, or none yet: replaced by renaming a temporary file over this path (the
    /// output's path with its symbolic links followed).
    Regular(PathBuf),
    /// A device, FIFO, socket or terminal: opened and written through.
    Special(PathBuf),
}

/// What `path` names once its symbolic links are followed.
fn target(path: &Path) -> Result<Target> {
    let mut p = path.to_path_buf();
    for _ in 0..MAX_LINKS {
        let meta = match std::fs::symlink_metadata(&p) {
            Ok(m) => m,
            // Nothing there yet (or a file where a folder should be, which the folder check
            // and the write itself report).
            Err(e) if matches!(e.kind(), std::io::ErrorKind::NotFound | std::io::ErrorKind::NotADirectory) => {
                return Ok(Target::Regular(p))
            }
            Err(e) => return Err(Error::in_file(path, format!("cannot look at the output: {e}"))),
        };
        let kind = meta.file_type();
        if kind.is_symlink() {
            // Through the kernel first: /proc's links (/dev/stdout → /proc/self/fd/1 → "pipe:[…]")
            // name no path, but opening them reaches the right object.
            match std::fs::metadata(&p) {
                Ok(m) if m.is_dir() => return Err(is_folder(path)),
                Ok(m) if !m.is_file() => return Ok(Target::Special(p)),
                _ => {}
            }
            let link = std::fs::read_link(&p)
                .map_err(|e| Error::in_file(path, format!("cannot read the symbolic link {}: {e}", p.display())))?;
            p = match p.parent() {
                Some(dir) if link.is_relative() => dir.join(link),
                _ => link,
            };
        } else if kind.is_dir() {
            return Err(is_folder(path));
        } else if kind.is_file() {
            return Ok(Target::Regular(p));
        } else {
            return Ok(Target::Special(p));
        }
    }
    Err(Error::in_file(path, format!("passes through more than {MAX_LINKS} symbolic links")))
}

fn is_folder(path: &Path) -> Error {
    Error::in_file(path, "is a folder; give a file name for the output")
}

/// Checks that an output's file name is not longer than file systems take, before any work is
/// done for it.
pub fn check_file_name(path: &Path) -> Result<()> {
    let len = path.file_name().map_or(0, |n| n.len());
    if len > MAX_FILE_NAME_BYTES {
        return Err(Error::in_file(
            path,
            format!("the file name is {len} bytes long; file systems take at most {MAX_FILE_NAME_BYTES}"),
        ));
    }
    Ok(())
}

/// Checks, before any work is done for it, that an output can be written: a legal file name,
/// not a folder, and a folder that exists and takes new files (tried by creating and removing
/// the output's temporary file). Special files are not opened here (opening a FIFO waits for
/// its reader).
pub fn check_output(path: &Path) -> Result<()> {
    check_file_name(path)?;
    let Target::Regular(p) = target(path)? else { return Ok(()) };
    let dir = folder_of(&p);
    match std::fs::metadata(dir) {
        Ok(m) if m.is_dir() => {}
        Ok(_) => return Err(Error::in_file(path, format!("{} is not a folder", dir.display()))),
        Err(_) => return Err(Error::in_file(path, format!("the folder {} does not exist", dir.display()))),
    }
    let probe = temp_beside(&p);
    match OpenOptions::new().write(true).create_new(true).open(&probe) {
        Ok(_) => {
            let _ = std::fs::remove_file(&probe);
            Ok(())
        }
        Err(e) => Err(Error::in_file(path, format!("cannot write in the folder {}: {e}", dir.display()))),
    }
}

/// The file an output names, as an absolute path with its links followed (its folder's, when
/// the file does not exist yet): two outputs, or an output and an input, are one file exactly
/// when these are equal.
pub fn resolved(path: &Path) -> PathBuf {
    path.canonicalize()
        .ok()
        .or_else(|| Some(folder_of(path).canonicalize().ok()?.join(path.file_name()?)))
        .unwrap_or_else(|| path.to_path_buf())
}

fn folder_of(p: &Path) -> &Path {
    match p.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    }
}

/// A number no other temporary file of this process has (two outputs staged for one target
/// must not share a temporary file).
fn next_temp_number() -> u64 {
    static NEXT: AtomicU64 = AtomicU64::new(0);
    NEXT.fetch_add(1, Ordering::Relaxed)
}

/// The temporary file beside `path`: its name, cut short enough that the temporary name itself
/// is a legal file name whenever `path`'s is, then the process id and a serial number.
fn temp_beside(path: &Path) -> PathBuf {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let mut cut = name.len().min(MAX_FILE_NAME_BYTES - 40);
    while !name.is_char_boundary(cut) {
        cut -= 1;
    }
    path.with_file_name(format!(".{}.{}.{}.tmp", &name[..cut], std::process::id(), next_temp_number()))
}

/// A temporary file for a special target, in the system's temporary folder (a device's own
/// folder, such as /dev, takes no new files).
fn temp_elsewhere() -> PathBuf {
    std::env::temp_dir().join(format!(".tessera.{}.{}.tmp", std::process::id(), next_temp_number()))
}

/// Temporary files that exist now: written or being written, not yet renamed or removed.
static LIVE: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

fn live() -> std::sync::MutexGuard<'static, Vec<PathBuf>> {
    LIVE.lock().unwrap_or_else(|e| e.into_inner())
}

fn forget(tmp: &Path) {
    live().retain(|p| p != tmp);
}

/// Removes every temporary file this process is writing or has staged. For a signal handler:
/// an interrupted run leaves no `.NAME.PID.N.tmp` behind (the final files are untouched).
pub fn remove_temporaries() {
    for p in live().drain(..) {
        let _ = std::fs::remove_file(p);
    }
}

/// A finished temporary file and the output it becomes.
struct Staged {
    tmp: PathBuf,
    target: Target,
    /// The output as the caller named it, for messages.
    path: PathBuf,
}

impl Staged {
    /// Moves the file into place: a rename over a regular file, a copy into a special one.
    fn commit(self) -> Result<()> {
        let done = match &self.target {
            Target::Regular(p) => std::fs::rename(&self.tmp, p)
                .map_err(|e| Error::in_file(&self.path, format!("cannot move the finished file into place: {e}"))),
            Target::Special(p) => (|| {
                let mut from = std::fs::File::open(&self.tmp)?;
                let mut to = OpenOptions::new().write(true).open(p)?;
                std::io::copy(&mut from, &mut to).map(|_| ())
            })()
            .map_err(|e| Error::in_file(&self.path, format!("cannot write: {e}"))),
        };
        let _ = std::fs::remove_file(&self.tmp);
        forget(&self.tmp);
        done
    }

    fn discard(self) {
        let _ = std::fs::remove_file(&self.tmp);
        forget(&self.tmp);
    }
}

thread_local! {
    /// The files staged by this thread's open [`OutputBatch`] (`None`: no batch open).
    static BATCH: RefCell<Option<Vec<Staged>>> = const { RefCell::new(None) };
}

/// Writes an output by `write`ing a temporary file and moving it into place (see the module's
/// notes for symbolic links and special files); inside an [`OutputBatch`], the move waits for
/// the batch's commit.
pub fn write_through_temp(path: &Path, write: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
    let target = target(path)?;
    let tmp = match &target {
        Target::Regular(p) => temp_beside(p),
        Target::Special(_) => temp_elsewhere(),
    };
    live().push(tmp.clone());
    let staged = Staged { tmp, target, path: path.to_path_buf() };
    if let Err(e) = write(&staged.tmp) {
        staged.discard();
        return Err(e);
    }
    // Inside a batch the file waits for the batch's commit; otherwise it goes into place now.
    let mut staged = Some(staged);
    BATCH.with(|b| {
        if let Some(batch) = b.borrow_mut().as_mut() {
            batch.extend(staged.take());
        }
    });
    staged.map_or(Ok(()), Staged::commit)
}

/// Outputs written together: while it is open, every file this thread writes through
/// [`write_through_temp`] is staged, and [`OutputBatch::commit`] moves them all into place;
/// dropped without a commit (an error on the way), it removes them and no output changes.
pub struct OutputBatch {
    open: bool,
}

impl OutputBatch {
    /// Opens a batch on this thread. Batches do not nest: an inner one joins the outer one
    /// (its commit does nothing; the outer commit moves everything).
    pub fn begin() -> OutputBatch {
        let open = BATCH.with(|b| {
            let mut b = b.borrow_mut();
            if b.is_some() {
                false
            } else {
                *b = Some(Vec::new());
                true
            }
        });
        OutputBatch { open }
    }

    /// Moves every staged file into place, in the order they were written. A file that cannot
    /// be moved stops the commit: the ones after it are removed, and the error says which
    /// outputs had already been replaced.
    pub fn commit(mut self) -> Result<()> {
        if !self.open {
            return Ok(());
        }
        self.open = false;
        let staged = BATCH.with(|b| b.borrow_mut().take()).unwrap_or_default();
        let mut done: Vec<PathBuf> = Vec::new();
        let mut rest = staged.into_iter();
        while let Some(s) = rest.next() {
            let path = s.path.clone();
            if let Err(e) = s.commit() {
                rest.for_each(Staged::discard);
                if done.is_empty() {
                    return Err(e);
                }
                let names: Vec<String> = done.iter().map(|p| p.display().to_string()).collect();
                return Err(Error::in_file(&path, format!("{e}; already written: {}", names.join(", "))));
            }
            done.push(path);
        }
        Ok(())
    }
}

impl Drop for OutputBatch {
    fn drop(&mut self) {
        if self.open {
            for s in BATCH.with(|b| b.borrow_mut().take()).unwrap_or_default() {
                s.discard();
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("tessera-output-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn write(path: &Path, text: &str) -> Result<()> {
        write_through_temp(path, |tmp| std::fs::write(tmp, text).map_err(|e| Error::in_file(tmp, e.to_string())))
    }

    /// Names in `d` other than `keep`: what a write left behind.
    fn leftovers(d: &Path, keep: &[&str]) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| !keep.contains(&n.as_str()))
            .collect();
        v.sort();
        v
    }

    #[test]
    fn links_are_followed_and_special_files_written_through() {
        let d = dir("links");
        std::fs::write(d.join("real.txt"), "old").unwrap();
        std::os::unix::fs::symlink("real.txt", d.join("link.txt")).unwrap();
        std::os::unix::fs::symlink("link.txt", d.join("link2.txt")).unwrap();
        write(&d.join("link2.txt"), "new").unwrap();
        assert!(std::fs::symlink_metadata(d.join("link.txt")).unwrap().file_type().is_symlink());
        assert!(std::fs::symlink_metadata(d.join("link2.txt")).unwrap().file_type().is_symlink());
        assert_eq!(std::fs::read_to_string(d.join("real.txt")).unwrap(), "new");
        // A dangling link creates the file it names.
        std::os::unix::fs::symlink("sub/made.txt", d.join("dangling.txt")).unwrap();
        std::fs::create_dir(d.join("sub")).unwrap();
        write(&d.join("dangling.txt"), "made").unwrap();
        assert_eq!(std::fs::read_to_string(d.join("sub/made.txt")).unwrap(), "made");
        assert_eq!(leftovers(&d, &["real.txt", "link.txt", "link2.txt", "dangling.txt", "sub"]), Vec::<String>::new());
        // A loop of links and a folder are errors naming the output.
        std::os::unix::fs::symlink("b.txt", d.join("a.txt")).unwrap();
        std::os::unix::fs::symlink("a.txt", d.join("b.txt")).unwrap();
        let e = write(&d.join("a.txt"), "x").unwrap_err().to_string();
        assert!(e.contains("a.txt") && e.contains("symbolic links"), "{e}");
        let e = write(&d.join("sub"), "x").unwrap_err().to_string();
        assert!(e.contains("is a folder"), "{e}");
        // A device is written through, not replaced by a regular file (as root a rename would
        // have replaced it).
        write(Path::new("/dev/null"), "gone").unwrap();
        let meta = std::fs::symlink_metadata("/dev/null").unwrap();
        assert!(!meta.is_file() && !meta.file_type().is_symlink(), "/dev/null is no longer a device");
        assert!(!live().iter().any(|p| p.starts_with(&d) || p.to_string_lossy().contains(".tessera.")));
    }

    #[test]
    fn a_batch_moves_every_file_or_none() {
        let d = dir("batch");
        for n in ["a.txt", "b.txt"] {
            std::fs::write(d.join(n), "old").unwrap();
        }
        // The second output fails: the first keeps its old content, and no temporary is left.
        {
            let batch = OutputBatch::begin();
            write(&d.join("a.txt"), "new").unwrap();
            assert_eq!(std::fs::read_to_string(d.join("a.txt")).unwrap(), "old", "moved before the commit");
            let e = write_through_temp(&d.join("b.txt"), |_| Err(Error::in_file(&d.join("b.txt"), "disk full")));
            assert!(e.is_err());
            drop(batch);
        }
        assert_eq!(std::fs::read_to_string(d.join("a.txt")).unwrap(), "old");
        assert_eq!(std::fs::read_to_string(d.join("b.txt")).unwrap(), "old");
        assert_eq!(leftovers(&d, &["a.txt", "b.txt"]), Vec::<String>::new());
        // Both succeed: both move at the commit.
        let batch = OutputBatch::begin();
        write(&d.join("a.txt"), "A").unwrap();
        write(&d.join("b.txt"), "B").unwrap();
        let inner = OutputBatch::begin();
        inner.commit().unwrap();
        assert_eq!(std::fs::read_to_string(d.join("b.txt")).unwrap(), "old", "an inner batch committed");
        batch.commit().unwrap();
        assert_eq!(std::fs::read_to_string(d.join("a.txt")).unwrap(), "A");
        assert_eq!(std::fs::read_to_string(d.join("b.txt")).unwrap(), "B");
        assert_eq!(leftovers(&d, &["a.txt", "b.txt"]), Vec::<String>::new());
        // Outside a batch a file moves at once.
        write(&d.join("a.txt"), "now").unwrap();
        assert_eq!(std::fs::read_to_string(d.join("a.txt")).unwrap(), "now");
    }

    #[test]
    fn staged_temporaries_are_registered_until_moved() {
        let d = dir("live");
        let batch = OutputBatch::begin();
        write(&d.join("a.txt"), "A").unwrap();
        let staged: Vec<PathBuf> = live().iter().filter(|p| p.starts_with(&d)).cloned().collect();
        assert_eq!(staged.len(), 1);
        assert!(staged[0].is_file());
        drop(batch);
        assert!(!staged[0].exists() && !live().contains(&staged[0]));
    }

    #[test]
    fn outputs_are_checked_before_any_work() {
        let d = dir("check");
        check_output(&d.join("fine.exr")).unwrap();
        assert_eq!(leftovers(&d, &[]), Vec::<String>::new(), "the probe was left behind");
        let e = check_output(&d.join("missing/x.exr")).unwrap_err().to_string();
        assert!(e.contains("missing") && e.contains("does not exist"), "{e}");
        std::fs::write(d.join("file"), "").unwrap();
        let e = check_output(&d.join("file/x.exr")).unwrap_err().to_string();
        assert!(e.contains("is not a folder"), "{e}");
        let e = check_output(&d).unwrap_err().to_string();
        assert!(e.contains("is a folder"), "{e}");
        check_output(Path::new("/dev/null")).unwrap();
        let e = check_output(&d.join(format!("{}.exr", "n".repeat(260)))).unwrap_err().to_string();
        assert!(e.contains("at most 255"), "{e}");
    }
}
