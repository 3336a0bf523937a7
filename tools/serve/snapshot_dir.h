// Where `arbor serve` writes what a command on the bus asks for (command_t SNAPSHOT): only inside
// the directory the operator named (--snapshot-dir), only under a plain file name, and never over
// a file this process did not create. A name is plain when it is 1 to 255 characters of letters,
// digits and . _ - +, not starting with '.' (so no separator, no "..", no hidden file).
// A file is written to a temporary name created with O_EXCL|O_NOFOLLOW, through its own
// descriptor, then put in place: linked under the new name (link() never replaces anything: a
// file, a symlink or a device already there refuses it), or renamed over a file this process
// wrote earlier under that name and that is still the same inode — it holds a descriptor on
// each file it wrote, so that inode number cannot be reused by another file meanwhile. At most
// kMaxNames names (a bound on descriptors and on disk use); a new name beyond is refused.
// Not thread-safe.
#pragma once

#include <cstddef>
#include <functional>
#include <map>
#include <string>
#include <utility>

#include <sys/types.h>

namespace arbor::serve {

class SnapshotDir {
 public:
  static constexpr std::size_t kMaxNames = 64;

  SnapshotDir() = default;  ///< unset: every write refused
  explicit SnapshotDir(std::string dir) : dir_(std::move(dir)) {}
  ~SnapshotDir();
  SnapshotDir(const SnapshotDir&) = delete;
  SnapshotDir& operator=(const SnapshotDir&) = delete;

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
  std::map<std::string, int> created_;  ///< name -> a descriptor on the file we wrote there
  long temporaries_ = 0;
};

}  // namespace arbor::serve
