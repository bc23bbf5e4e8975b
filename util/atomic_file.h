// Crash-safe writes: data goes to a temporary name in the same folder, is flushed to disk,
// then renamed over the target, so a reader sees either the old file or the whole new one.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

namespace paircast {

// Whether a write is flushed to the disk before it is renamed into place. Either way a killed
// process leaves the old file or the whole new one; only Sync also survives a power loss.
enum class Durability { Sync, NoSync };

// Writes `data` to `path` atomically. Throws paircast::Error naming `path` on failure (a full
// disk included) and leaves no temporary file behind.
void writeFileAtomic(const std::string& path, std::string_view data,
                     Durability durability = Durability::Sync);

// The temporary name used for `path` by this process: "<dir>/.<name>.tmp.<host>.<pid>", <host>
// being this machine's host name with any character other than a letter, digit, '-' or '_' as
// '_'. The host makes the pid mean something on a shared file system; which part of a job wrote
// it is in <name> (pairs-1-000042.tar) or its folder.
std::string tempPathFor(const std::string& path);

// Removes the temporary files in `dir` (not its subfolders) that a killed writer left of the files
// that `owned` accepts by name ("pairs-1-000042.tar"; every file when `owned` is empty), so that
// a caller touches only its own files in a folder that others write into. A temporary from this
// host is kept while its pid runs; one from another host is removed, the caller owning the file.
// The older ".<name>.tmp.<pid>" counts as this host's. Returns how many were removed.
int removeStaleTemporaries(const std::string& dir,
                           const std::function<bool(const std::string&)>& owned = {});

// Test-only fault injection: when the environment variable PAIRCAST_FAULT_KILL_DURING_WRITE holds
// a string that the path contains, the process writes half of the data to the temporary file
// and then kills itself with SIGKILL, as a crash or kill -9 in the middle of a write would.
// (tests/reliability/fault_injection_test.cpp uses it on checkpoints and shards.)
void faultPointDuringWrite(const std::string& path, int fd, std::string_view data);

// Renames `from` to `to` after fsync-ing `from`, then fsyncs the folder.
void commitFile(const std::string& from, const std::string& to);

// Reads a whole file. Throws paircast::Error naming `path` when it cannot be read.
std::string readFile(const std::string& path);

// Creates a folder and its parents. Throws paircast::Error naming `path` on failure.
void makeDirs(const std::string& path);

}  // namespace paircast
