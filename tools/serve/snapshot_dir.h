// Where `arbor serve` writes what a command on the bus asks for (command_t SNAPSHOT): only inside
// the directory the operator named (--snapshot-dir), only under a plain file name, and never over
// a file this process did not create. A name is plain when it is 1 to 255 characters of letters,
// digits and . _ - +, not starting with '.' (so no separator, no "..", no hidden file).
// A file is written to a temporary name created with O_EXCL|O_NOFOLLOW, through its own
// descriptor, then put in place: linked under the new name (link() never replaces anything: a
// file, a symlink or a device already there refuses it), or renamed over a file this process
// wrote earlier under that name and that is still the same inode. Not thread-safe.
#pragma once

#include <functional>
#include <map>
#include <string>
#include <utility>

#include <sys/types.h>

namespace arbor::serve {

class SnapshotDir {
 public:
  SnapshotDir() = default;  ///< unset: every write refused
  explicit SnapshotDir(std::string dir) : dir_(std::move(dir)) {}

  bool enabled() const { return !dir_.empty(); }
  const std::string& dir() const { return dir_; }
  /// "" when `name` is a plain file name, else why not.
  static std::string checkName(const std::string& name);
  /// Writes `name` inside the directory: `write` is handed a path to a new, empty file of ours
  /// and writes the whole file there. Returns "" when `name` now holds it, else why it was
  /// refused (nothing of it is left in the directory). Exceptions of `write` are refusals.
  std::string write(const std::string& name, const std::function<void(const std::string&)>& write);
  /// `name` as a log line may show it (non-printable bytes as '?', at most 80 characters).
  static std::string printable(const std::string& name);

 private:
  std::string dir_;
  std::map<std::string, std::pair<dev_t, ino_t>> created_;  ///< name -> the file we wrote there
  long temporaries_ = 0;
};

}  // namespace arbor::serve
