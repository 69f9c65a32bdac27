//! Files: a document's includes, read depth first, and the files its inputs name.

use super::importer::{Fail, Importer};
use super::LoadOptions;
use crate::error::{LoadError, LoadErrorKind, Location};
use roxmltree::Node as XNode;
use std::path::{Path, PathBuf};

pub(super) const XINCLUDE_NS: &str = "http://www.w3.org/2001/XInclude";

pub(super) fn read_text(path: &Path, at: &Location) -> Result<String, LoadError> {
    let bytes = std::fs::read(path).map_err(|e| LoadError {
        location: at.clone(),
        kind: if e.kind() == std::io::ErrorKind::NotFound {
            LoadErrorKind::MissingFile(path.to_path_buf())
        } else {
            LoadErrorKind::Io(format!("{}: {e}", path.display()))
        },
    })?;
    crate::text::utf8_text(bytes).map_err(|e| LoadError {
        location: Location { file: path.to_path_buf(), line: e.line, column: e.column },
        kind: LoadErrorKind::Io(e.message),
    })
}

pub(super) fn parse_xml<'i>(text: &'i str, path: &Path) -> Result<roxmltree::Document<'i>, LoadError> {
    roxmltree::Document::parse(text).map_err(|e| {
        let p = e.pos();
        LoadError {
            location: Location { file: path.to_path_buf(), line: p.row, column: p.col },
            kind: LoadErrorKind::Xml(e.to_string()),
        }
    })
}

fn canonical(p: &Path) -> PathBuf {
    p.canonicalize().unwrap_or_else(|_| p.to_path_buf())
}

/// Reads `text` (from `path`) and, depth first, every file it includes, into `out`.
pub(super) fn gather(
    text: String,
    path: &Path,
    opts: &LoadOptions,
    out: &mut Vec<(PathBuf, String)>,
    stack: &mut Vec<PathBuf>,
) -> Result<(), LoadError> {
    let includes: Vec<(String, Location)> = {
        let xml = parse_xml(&text, path)?;
        let mut v = Vec::new();
        for el in xml.root_element().children().filter(|c| c.is_element()) {
            let t = el.tag_name();
            if t.name() == "include" && t.namespace() == Some(XINCLUDE_NS) {
                let p = xml.text_pos_at(el.range().start);
                let loc = Location { file: path.to_path_buf(), line: p.row, column: p.col };
                let Some(href) = el.attribute("href") else {
                    return Err(LoadError {
                        location: loc,
                        kind: LoadErrorKind::Structure("xi:include has no href attribute".into()),
                    });
                };
                v.push((href.to_string(), loc));
            }
        }
        v
    };
    stack.push(canonical(path));
    out.push((path.to_path_buf(), text));
    for (href, loc) in includes {
        let base = path.parent().unwrap_or(Path::new("."));
        let found = std::iter::once(base.join(&href))
            .chain(opts.search_paths.iter().map(|s| s.join(&href)))
            .find(|p| p.is_file());
        let Some(file) = found else {
            return Err(LoadError { location: loc, kind: LoadErrorKind::MissingFile(PathBuf::from(href)) });
        };
        let c = canonical(&file);
        if stack.contains(&c) {
            return Err(LoadError {
                location: loc,
                kind: LoadErrorKind::Structure(format!(
                    "include cycle: `{}` includes itself (through {})",
                    file.display(),
                    stack.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(" → ")
                )),
            });
        }
        if out.iter().any(|(p, _)| canonical(p) == c) {
            continue;
        }
        let t = read_text(&file, &loc)?;
        gather(t, &file, opts, out, stack)?;
    }
    stack.pop();
    Ok(())
}

impl<'a, 'i> Importer<'a, 'i> {
    /// Finds a referenced file: `fileprefix` (the nearest on `at` or its ancestors) prepended,
    /// looked up beside the file naming it, beside the document, then in the search paths.
    pub(super) fn resolve_file(&self, at: XNode<'a, 'i>, value: &str) -> Result<PathBuf, Fail> {
        let prefix = at.ancestors().find_map(|a| a.attribute("fileprefix")).unwrap_or("");
        let name = format!("{prefix}{value}");
        let own = self.paths[self.doc_index(at)].parent().unwrap_or(Path::new(".")).to_path_buf();
        let main = self.paths[0].parent().unwrap_or(Path::new(".")).to_path_buf();
        std::iter::once(own.join(&name))
            .chain(std::iter::once(main.join(&name)))
            .chain(self.opts.search_paths.iter().map(|s| s.join(&name)))
            .find(|p| p.is_file())
            .ok_or_else(|| self.hard(at, LoadErrorKind::MissingFile(PathBuf::from(name))))
    }
}
