// Atomic outputs (output_set.hpp).
#include "flatland/files/output_set.hpp"

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <mutex>
#include <stdexcept>
#include <system_error>

#include <fcntl.h>
#include <stdio.h>
#include <unistd.h>

namespace flatland::files {

namespace {

/// What an interruption must remove: the staging directories of every live OutputSet and the
/// directories they created. Never destroyed (an interrupt handler's thread may use it while the
/// main thread runs static destructors).
struct Registry {
  std::mutex mutex;
  std::vector<fs::path> staging;  // remove_all
  std::vector<fs::path> created;  // rmdir if empty, last first
};

Registry& registry() {
  static Registry* r = new Registry;
  return *r;
}

void erase_value(std::vector<fs::path>& v, const fs::path& p) {
  v.erase(std::remove(v.begin(), v.end(), p), v.end());
}

/// remove_all, retried: a writer thread (the recorder's PNG encoder) may add a file between the
/// listing and the rmdir.
void remove_tree(const fs::path& p) {
  std::error_code ec;
  for (int i = 0; i < 5; ++i) {
    fs::remove_all(p, ec);
    if (!ec && !fs::exists(p, ec)) return;
  }
}

fs::path normal_absolute(const fs::path& p) {
  fs::path a = fs::absolute(p).lexically_normal();
  if (a.filename().empty() && a.has_parent_path() && a != a.root_path()) a = a.parent_path();
  return a;
}

/// True (and `rel` set) if `p` is `base` or inside it; both absolute and normal.
bool inside(const fs::path& p, const fs::path& base, fs::path& rel) {
  auto pi = p.begin();
  for (auto bi = base.begin(); bi != base.end(); ++bi, ++pi)
    if (pi == p.end() || *pi != *bi) return false;
  rel.clear();
  for (; pi != p.end(); ++pi) rel /= *pi;
  return true;
}

/// renameat2 with `flags`; falls back to the plain-rename equivalent where the file system does
/// not support the flag. Returns 0 or an errno value.
int rename_with(const fs::path& from, const fs::path& to, unsigned flags) {
  if (::renameat2(AT_FDCWD, from.c_str(), AT_FDCWD, to.c_str(), flags) == 0) return 0;
  const int err = errno;
  if (err != EINVAL && err != ENOSYS) return err;
  if (flags & RENAME_NOREPLACE) {
    std::error_code ec;
    if (fs::exists(to, ec)) return EEXIST;
  }
  if (flags & RENAME_EXCHANGE) return err;  // the caller falls back to two renames
  return ::rename(from.c_str(), to.c_str()) == 0 ? 0 : errno;
}

}  // namespace

bool abandon_outputs(const std::function<void()>& before) {
  Registry& r = registry();
  // Taken while commit() runs: the outputs are then all in place and nothing is removed.
  std::lock_guard lock(r.mutex);
  if (before) before();
  for (const fs::path& p : r.staging) remove_tree(p);
  std::error_code ec;
  for (auto it = r.created.rbegin(); it != r.created.rend(); ++it) fs::remove(*it, ec);
  return !r.staging.empty();
}

OutputSet::~OutputSet() {
  if (committed_) return;
  Registry& r = registry();
  std::lock_guard lock(r.mutex);
  std::error_code ec;
  for (const Dir& d : dirs_) {
    remove_tree(d.staging);
    erase_value(r.staging, d.staging);
  }
  // Innermost first; remove() refuses non-empty directories, which is what we want.
  for (auto it = created_dirs_.rbegin(); it != created_dirs_.rend(); ++it) {
    fs::remove(*it, ec);
    erase_value(r.created, *it);
  }
}

void OutputSet::ensure_directory(const fs::path& dir) {
  if (dir.empty()) return;
  const fs::path abs = normal_absolute(dir);
  fs::path rel;
  for (const Dir& d : dirs_)
    if (d.is_output && inside(abs, d.final_path, rel)) {
      std::error_code ec;
      fs::create_directories(d.content / rel, ec);
      if (ec)
        throw std::runtime_error("cannot create " + (d.content / rel).string() + ": " +
                                 ec.message());
      return;
    }
  // Record the missing ancestors (outermost first) before creating them.
  std::vector<fs::path> missing;
  for (fs::path p = abs; !p.empty() && !fs::exists(p); p = p.parent_path()) {
    missing.insert(missing.begin(), p);
    if (p == p.parent_path()) break;
  }
  Registry& r = registry();
  std::lock_guard lock(r.mutex);
  std::error_code ec;
  fs::create_directories(abs, ec);
  created_dirs_.insert(created_dirs_.end(), missing.begin(), missing.end());
  r.created.insert(r.created.end(), missing.begin(), missing.end());
  if (ec || !fs::is_directory(abs))
    throw std::runtime_error("cannot create output directory " + dir.string() + ": " +
                             (ec ? ec.message() : "not a directory"));
}

fs::path OutputSet::begin_directory(const fs::path& dir, bool nested) {
  const fs::path abs = normal_absolute(dir);
  ensure_directory(abs.parent_path());
  // Built piecewise: "." + std::string&& trips GCC 12's -Wrestrict false positive.
  std::string name = ".";
  name += abs.filename().string();
  name += ".tmp-";
  name += std::to_string(::getpid());
  const fs::path staging = abs.parent_path() / name;
  Registry& r = registry();
  std::lock_guard lock(r.mutex);
  remove_tree(staging);  // a leftover of a killed run that had our pid
  std::error_code ec;
  if (!fs::create_directory(staging, ec))
    throw std::runtime_error("cannot create the staging directory " + staging.string() + ": " +
                             (ec ? ec.message() : "exists"));
  const fs::path content = nested ? staging / "content" : staging;
  dirs_.push_back({staging, content, abs, true});
  r.staging.push_back(staging);
  return content;
}

fs::path OutputSet::file_staging_dir(const fs::path& parent) {
  for (const Dir& d : dirs_)
    if (!d.is_output && d.final_path == parent) return d.staging;
  ensure_directory(parent);
  const fs::path staging = parent / (".flatland.tmp-" + std::to_string(::getpid()));
  Registry& r = registry();
  std::lock_guard lock(r.mutex);
  remove_tree(staging);
  std::error_code ec;
  if (!fs::create_directory(staging, ec))
    throw std::runtime_error("cannot create the staging directory " + staging.string() + ": " +
                             (ec ? ec.message() : "exists"));
  dirs_.push_back({staging, staging, parent, false});
  r.staging.push_back(staging);
  return staging;
}

fs::path OutputSet::map_path(const fs::path& final_path) {
  const fs::path abs = normal_absolute(final_path);
  fs::path rel;
  for (const Dir& d : dirs_)
    if (d.is_output && inside(abs, d.final_path, rel)) return d.content / rel;
  return file_staging_dir(abs.parent_path()) / abs.filename();
}

fs::path OutputSet::reserve(const fs::path& final_path) {
  const fs::path tmp = map_path(final_path);
  files_.emplace_back(tmp, final_path);
  return tmp;
}

fs::path OutputSet::temp_path(const fs::path& final_path) const {
  for (const auto& [tmp, fin] : files_)
    if (fin == final_path) return tmp;
  return {};
}

fs::path OutputSet::stage(const fs::path& final_path, const std::string& content) {
  const fs::path tmp = reserve(final_path);
  std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
  if (!f) throw std::runtime_error("cannot write " + tmp.string());
  f << content;
  f.close();
  if (!f) throw std::runtime_error("error writing " + tmp.string());
  return tmp;
}

void OutputSet::commit() {
  Registry& r = registry();
  std::lock_guard lock(r.mutex);
  const unsigned no_replace = force_ ? 0u : RENAME_NOREPLACE;
  // Files first (each rename(2) is atomic), then the directory outputs.
  for (const auto& [tmp, final_path] : files_) {
    bool in_output_dir = false;
    fs::path rel;
    for (const Dir& d : dirs_)
      in_output_dir = in_output_dir || (d.is_output && inside(tmp, d.content, rel));
    if (in_output_dir) continue;  // moves with its directory
    const int err = rename_with(tmp, final_path, no_replace);
    if (err == EEXIST)
      throw std::invalid_argument(final_path.string() +
                                  " appeared while flatland ran; pass --force to replace it");
    if (err)
      throw std::runtime_error("cannot rename " + tmp.string() + " to " + final_path.string() +
                               ": " + std::strerror(err));
  }
  for (const Dir& d : dirs_) {
    if (!d.is_output) continue;
    std::error_code ec;
    int err = 0;
    if (!fs::exists(d.final_path, ec)) {
      err = rename_with(d.content, d.final_path, RENAME_NOREPLACE);
    } else if (fs::is_directory(d.final_path, ec) && fs::is_empty(d.final_path, ec)) {
      err = ::rename(d.content.c_str(), d.final_path.c_str()) == 0 ? 0 : errno;  // replaces it
    } else if (!force_) {
      err = EEXIST;
    } else {
      // Swap in one step; the old tree ends up at the content path and goes with the staging.
      err = rename_with(d.content, d.final_path, RENAME_EXCHANGE);
      if (err == EINVAL || err == ENOSYS) {
        fs::path old = d.staging;
        old += ".old";
        err = ::rename(d.final_path.c_str(), old.c_str()) == 0 ? 0 : errno;
        if (!err) err = ::rename(d.content.c_str(), d.final_path.c_str()) == 0 ? 0 : errno;
        if (!err) remove_tree(old);
      }
    }
    if (err == EEXIST || err == ENOTEMPTY)
      throw std::invalid_argument(d.final_path.string() +
                                  " appeared while flatland ran; pass --force to replace it");
    if (err)
      throw std::runtime_error("cannot move " + d.content.string() + " to " +
                               d.final_path.string() + ": " + std::strerror(err));
  }
  std::error_code ec;
  for (const Dir& d : dirs_) {
    // File staging directories are empty now; a directory output's staging is gone (moved) or
    // holds the replaced tree or the nested staging root.
    if (d.is_output && fs::exists(d.staging, ec))
      remove_tree(d.staging);
    else
      fs::remove(d.staging, ec);
    erase_value(r.staging, d.staging);
  }
  for (const fs::path& p : created_dirs_) erase_value(r.created, p);
  committed_ = true;
}

std::vector<std::string> OutputSet::paths() const {
  std::vector<std::string> p;
  for (const auto& f : files_) p.push_back(f.second.string());
  return p;
}

}  // namespace flatland::files
