// Crash-safe writes: data goes to a temporary name in the same folder, is flushed to disk,
// then renamed over the target, so a reader sees either the old file or the whole new one.
#pragma once

#include <cstdint>
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

// The temporary name used for `path` by this process: "<dir>/.<name>.tmp.<pid>".
std::string tempPathFor(const std::string& path);

// Removes the temporary files ("<dir>/.<name>.tmp.<pid>") that killed processes left in `dir`
// (their pid no longer runs). Returns how many were removed.
int removeStaleTemporaries(const std::string& dir);

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
