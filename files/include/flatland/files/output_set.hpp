// One way to write outputs atomically: every file and directory a program writes is staged
// beside its final place and moved there in one rename at the end, or removed whole on failure or
// interruption. The CLI's outputs and the recorder's recordings both go through it.
#pragma once

#include <filesystem>
#include <functional>
#include <string>
#include <utility>
#include <vector>

namespace flatland::files {

namespace fs = std::filesystem;

/// Files a program writes, staged so that a failure or an interruption leaves nothing behind and
/// an existing output is replaced in one rename:
///  - a file output P/name is written as P/.flatland.tmp-<pid>/name and renamed over P/name by
///    commit() (rename(2) replaces atomically; without --force RENAME_NOREPLACE also refuses a
///    file that appeared while the program ran);
///  - a directory output D (begin_directory) is built as the sibling D's-parent/.D.tmp-<pid>, and
///    every file staged under D goes there under its final name; commit() renames it to D, or
///    with --force swaps it with the existing D (renameat2 RENAME_EXCHANGE) and removes the old
///    tree.
/// Until commit() the destructor removes the staging directories and any directory this set
/// created (if left empty), so an exception anywhere removes every output of the set. The
/// staging directories are also registered process-wide, so that an interrupt handler can remove
/// them before the process exits (abandon_outputs). commit() refuses an output that appeared
/// while the program ran (without force) with std::invalid_argument naming it; other file-system
/// failures are std::runtime_error naming the path.
class OutputSet {
 public:
  explicit OutputSet(bool force = false) : force_(force) {}
  OutputSet(const OutputSet&) = delete;
  OutputSet& operator=(const OutputSet&) = delete;
  ~OutputSet();

  /// Start the directory output `dir` (created at commit; its parents now). Returns the staging
  /// directory that stands for it until then. `nested`: the returned path does not exist yet and
  /// lies inside a registered staging root, for a writer that creates the directory itself and
  /// keeps its own temporaries beside it (the recorder).
  fs::path begin_directory(const fs::path& dir, bool nested = false);
  /// Create `dir` (and missing parents), remembering which directories were new. Inside a
  /// directory output, creates the staged counterpart instead.
  void ensure_directory(const fs::path& dir);
  /// Stage `content` for `final_path` (its directory must exist). Returns the temporary path.
  fs::path stage(const fs::path& final_path, const std::string& content);
  /// Reserve a temporary path for a file another program or library writes (gnuplot's PNGs, the
  /// camera file, the MP4 writer). The temporary keeps the file's name and extension.
  fs::path reserve(const fs::path& final_path);
  fs::path reserve_keep_extension(const fs::path& final_path) { return reserve(final_path); }
  /// The temporary path of an already staged or reserved final path (empty if none).
  fs::path temp_path(const fs::path& final_path) const;
  /// Move every staged file and directory into place.
  void commit();
  /// The final paths, in staging order.
  std::vector<std::string> paths() const;

 private:
  fs::path map_path(const fs::path& final_path);
  fs::path file_staging_dir(const fs::path& parent);

  struct Dir {
    fs::path staging;  // registered; removed on failure
    fs::path content;  // what becomes final_path (staging itself unless nested)
    fs::path final_path;
    bool is_output;  // a directory output (else the staging directory of file outputs)
  };
  bool force_;
  std::vector<std::pair<fs::path, fs::path>> files_;  // (temporary, final)
  std::vector<Dir> dirs_;
  std::vector<fs::path> created_dirs_;  // outermost first
  bool committed_ = false;
};

/// For an interrupt handler (a thread that reads the signal, not the handler itself): under the
/// lock that commit() holds, so that the outputs are either all in place or none, runs `before`
/// (stop a child process that writes into a staging directory, say), then removes every live
/// OutputSet's staging directories and the directories they created. Returns true if there were
/// any. The sets are unusable afterwards; the process is expected to exit.
bool abandon_outputs(const std::function<void()>& before = {});

}  // namespace flatland::files
