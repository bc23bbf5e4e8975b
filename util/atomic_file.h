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

// Renames `from` to `to` after fsync-ing `from`, then fsyncs the folder.
void commitFile(const std::string& from, const std::string& to);

// Reads a whole file. Throws paircast::Error naming `path` when it cannot be read.
std::string readFile(const std::string& path);

// Creates a folder and its parents. Throws paircast::Error naming `path` on failure.
void makeDirs(const std::string& path);

}  // namespace paircast
