#include "arbor_slam/tools/serve/snapshot_dir.h"

#include <cerrno>
#include <cstring>
#include <stdexcept>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace arbor::serve {
namespace {

bool plainChar(char c) {
  return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '.' ||
         c == '_' || c == '-' || c == '+';
}

std::string systemError(const std::string& what) { return what + ": " + std::strerror(errno); }

// Closes a descriptor on every path out.
struct Fd {
  int fd = -1;
  ~Fd() {
    if (fd >= 0) ::close(fd);
  }
};

}  // namespace

SnapshotDir::~SnapshotDir() {
  for (const auto& [name, fd] : created_) ::close(fd);
}

std::string SnapshotDir::printable(const std::string& name) {
  std::string out;
  for (char c : name.substr(0, 80)) out += (c >= 0x20 && c < 0x7f) ? c : '?';
  if (name.size() > 80) out += "...";
  return "'" + out + "'";
}

std::string SnapshotDir::checkName(const std::string& name) {
  if (name.empty()) return "no file name";
  if (name.size() > 255) return "file name longer than 255 characters";
  if (name.find('/') != std::string::npos) return "file name " + printable(name) + " has a '/'";
  if (name[0] == '.') {
    return "file name " + printable(name) + " starts with '.' (\"..\", hidden files)";
  }
  if (name[0] == '-' || name[0] == '+') {  // "-rf" in a directory is an option to `rm *`
    return "file name " + printable(name) + " starts with '" + name[0] +
           "' (a command line would read it as an option)";
  }
  for (char c : name) {
    if (!plainChar(c)) {
      return "file name " + printable(name) +
             " has a character other than letters, digits, . _ - +";
    }
  }
  return "";
}

std::string SnapshotDir::write(const std::string& name,
                               const std::function<void(const std::string&)>& write) {
  if (!enabled()) return "no --snapshot-dir: the service writes no file for the bus";
  if (std::string problem = checkName(name); !problem.empty()) return problem;
  const auto created = created_.find(name);
  if (created == created_.end() && created_.size() >= kMaxNames) {
    return "already " + std::to_string(kMaxNames) + " snapshot names written; no new one";
  }
  Fd dir;
  dir.fd = ::open(dir_.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dir.fd < 0) return systemError("cannot open --snapshot-dir " + dir_);
  // A temporary of ours: hidden, so no name from the bus can be it.
  const std::string temp = ".arbor-snapshot-" + std::to_string(::getpid()) + "-" +
                           std::to_string(++temporaries_) + ".tmp";
  Fd file;
  file.fd =
      ::openat(dir.fd, temp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0644);
  if (file.fd < 0) return systemError("cannot create a temporary file in " + dir_);
  const auto drop = [&] { ::unlinkat(dir.fd, temp.c_str(), 0); };
  try {
    // Through our own descriptor: whatever happens to the name meanwhile, this is our file.
    write("/proc/self/fd/" + std::to_string(file.fd));
  } catch (const std::exception& e) {
    drop();
    return std::string("the snapshot could not be written: ") + e.what();
  }
  if (::fsync(file.fd) != 0) {
    const std::string error = systemError("cannot fsync the snapshot");
    drop();
    return error;
  }
  struct stat there, before;
  const bool exists = ::fstatat(dir.fd, name.c_str(), &there, AT_SYMLINK_NOFOLLOW) == 0;
  if (exists && created != created_.end() && ::fstat(created->second, &before) == 0 &&
      there.st_dev == before.st_dev && there.st_ino == before.st_ino) {
    // A file this process wrote under that name, unchanged since: replaced in one step.
    if (::renameat(dir.fd, temp.c_str(), dir.fd, name.c_str()) != 0) {
      const std::string error = systemError("cannot replace " + printable(name));
      drop();
      return error;
    }
  } else if (::linkat(dir.fd, temp.c_str(), dir.fd, name.c_str(), 0) != 0) {
    // link() never replaces: a file, symlink or device already there refuses it.
    const std::string error = errno == EEXIST
                                  ? printable(name) + " exists and was not written by this service"
                                  : systemError("cannot create " + printable(name));
    drop();
    return error;
  } else {
    drop();  // the new name holds it now
  }
  if (created != created_.end()) ::close(created->second);
  created_[name] = file.fd;  // held: the inode stays ours to recognise
  file.fd = -1;
  return "";
}

}  // namespace arbor::serve
