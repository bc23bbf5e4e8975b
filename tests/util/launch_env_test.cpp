#include "util/launch_env.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdio>
#include <fstream>
#include <map>
#include <random>

#include "test_errors.h"
#include "test_paths.h"
#include "util/error.h"

namespace paircast {
namespace {

Environment envOf(std::map<std::string, std::string> vars) {
  return [vars = std::move(vars)](const std::string& name) -> std::optional<std::string> {
    const auto it = vars.find(name);
    if (it == vars.end() || it->second.empty()) return std::nullopt;
    return it->second;
  };
}

using Hosts = std::vector<std::string>;

// What Slurm 22.05's `scontrol show hostnames` prints for these lists.
TEST(SlurmHostList, ExpandsAsScontrolDoes) {
  const std::vector<std::pair<std::string, Hosts>> cases = {
      {"gpu[01-04,07],cpu3", {"gpu01", "gpu02", "gpu03", "gpu04", "gpu07", "cpu3"}},
      {"n[1-2]-r[3-4]", {"n1-r3", "n1-r4", "n2-r3", "n2-r4"}},
      {"rack[0-1]n[09-10]", {"rack0n09", "rack0n10", "rack1n09", "rack1n10"}},
      {"a[1-2][3-4]", {"a13", "a14", "a23", "a24"}},
      {"a[8-11]", {"a8", "a9", "a10", "a11"}},
      {"node[001-003]", {"node001", "node002", "node003"}},
      {"n[009-011]", {"n009", "n010", "n011"}},
      {"n[01-3]", {"n01", "n02", "n03"}},
      {"n[1-03]", {"n1", "n2", "n3"}},
      {"a,,b", {"a", "b"}},
      {"a b", {"a", "b"}},
      {"a[1-2],", {"a1", "a2"}},
      {"[1-2]", {"1", "2"}},
      {"localhost", {"localhost"}},
  };
  for (const auto& [list, hosts] : cases) EXPECT_EQ(expandSlurmHostList(list), hosts) << list;
  EXPECT_EQ(firstSlurmHost("gpu[01-04,07],cpu3"), "gpu01");
  EXPECT_EQ(firstSlurmHost("cpu3,gpu[01-04]"), "cpu3");
}

TEST(SlurmHostList, RefusesGarbageWithTheList) {
  for (const char* list : {"a[1-3", "a]", "a[3-1]", "a[]", "a[1,,2]", "a[x-2]", "a[1-2-3]",
                           "a[[1]]", "a[1 2]", "", ",", "n[0-2000000]", "a[0-999][0-9999]"}) {
    SCOPED_TRACE(list);
    EXPECT_ERROR_CONTAINS(expandSlurmHostList(list), std::string("'") + list + "'");
  }
  EXPECT_ERROR_CONTAINS(expandSlurmHostList("a[3-1]"), "runs backwards");
  EXPECT_ERROR_CONTAINS(expandSlurmHostList("a[1-3"), "not closed");
  EXPECT_ERROR_CONTAINS(expandSlurmHostList("a[x-2]"), "not a number");
}

// A random host list of bracket groups, ranges, zero padding and commas.
std::string randomHostList(std::mt19937& rng) {
  auto pick = [&](int n) { return static_cast<int>(rng() % n); };
  std::string list;
  for (int item = 0, items = 1 + pick(3); item < items; ++item) {
    if (item) list += ",";
    list += std::string(1, static_cast<char>('a' + pick(4))) + (pick(2) ? "n" : "");
    for (int g = 0, groups = pick(3); g < groups; ++g) {
      if (g) list += "-r";
      list += "[";
      for (int r = 0, ranges = 1 + pick(3); r < ranges; ++r) {
        const int width = 1 + pick(3), lo = pick(20), hi = lo + pick(4);
        char buf[32];
        std::snprintf(buf, sizeof buf, "%s%0*d", r ? "," : "", width, lo);
        list += buf;
        if (pick(2)) list += "-" + std::to_string(hi);
      }
      list += "]";
    }
  }
  return list;
}

// Slurm's own expansion of `list`, through scontrol with a minimal configuration.
Hosts scontrolHostnames(const std::string& conf, const std::string& list) {
  const std::string cmd =
      "SLURM_CONF=" + conf + " timeout 10 scontrol show hostnames '" + list + "' 2>&1";
  Hosts hosts;
  FILE* p = popen(cmd.c_str(), "r");
  char line[256];
  while (p && std::fgets(line, sizeof line, p)) {
    std::string h(line);
    while (!h.empty() && (h.back() == '\n' || h.back() == '\r')) h.pop_back();
    hosts.push_back(h);
  }
  if (p) pclose(p);
  return hosts;
}

TEST(SlurmHostList, MatchesScontrolOnRandomLists) {
  if (std::system("command -v scontrol >/dev/null 2>&1") != 0)
    GTEST_SKIP() << "scontrol is not installed (scripts/setup.sh installs slurm-client)";
  const std::string conf = testing::scratchDir("conf") + "/slurm.conf";
  std::ofstream(conf) << "ClusterName=paircast-test\nSlurmctldHost=localhost\n"
                         "AuthType=auth/none\nCredType=cred/none\n";
  std::mt19937 rng(7);
  for (int i = 0; i < 40; ++i) {
    const std::string list = randomHostList(rng);
    EXPECT_EQ(expandSlurmHostList(list), scontrolHostnames(conf, list)) << list;
  }
}

// ---- generation parts ----

std::map<std::string, std::string> slurmArray(const std::string& id, const std::string& min,
                                              const std::string& max, const std::string& count,
                                              const std::string& step = "1") {
  return {{"SLURM_ARRAY_TASK_ID", id},     {"SLURM_ARRAY_TASK_MIN", min},
          {"SLURM_ARRAY_TASK_MAX", max},   {"SLURM_ARRAY_TASK_COUNT", count},
          {"SLURM_ARRAY_TASK_STEP", step}, {"SLURM_JOB_ID", "41"}};
}

TEST(JobPart, SlurmArrayTaskLessItsMinimumOfItsCount) {
  // --array=4-6: task 5 is part 1 of 3.
  const JobPart p = jobPart(envOf(slurmArray("5", "4", "6", "3")), std::nullopt, std::nullopt);
  EXPECT_EQ(p.index, 1);
  EXPECT_EQ(p.count, 3);
  EXPECT_EQ(p.source, "Slurm array");
  EXPECT_NE(p.describe().find("part 1 of 3, from the Slurm array (SLURM_ARRAY_TASK_ID=5"),
            std::string::npos)
      << p.describe();
  // Every task of --array=0-9 once.
  for (int t = 0; t < 10; ++t) {
    const JobPart q =
        jobPart(envOf(slurmArray(std::to_string(t), "0", "9", "10")), std::nullopt, std::nullopt);
    EXPECT_EQ(q.index, t);
    EXPECT_EQ(q.count, 10);
  }
}

TEST(JobPart, FlagsGivenByHandWin) {
  const JobPart p = jobPart(envOf(slurmArray("5", "4", "6", "3")), 2, 5);
  EXPECT_EQ(p.index, 2);
  EXPECT_EQ(p.count, 5);
  EXPECT_EQ(p.source, "flags");
  const JobPart k = jobPart(envOf({{"JOB_COMPLETION_INDEX", "3"}}), 0, 4);
  EXPECT_EQ(k.index, 0);
  EXPECT_EQ(k.source, "flags");
}

TEST(JobPart, SteppedArraysAndArraysWithGapsAreRefused) {
  // --array=0-9:4 (tasks 0, 4, 8) and --array=1,4,5, as Slurm 22.05 sets them.
  EXPECT_ERROR_CONTAINS(
      jobPart(envOf(slurmArray("4", "0", "8", "3", "4")), std::nullopt, std::nullopt),
      "a Slurm array with a step or gaps");
  EXPECT_ERROR_CONTAINS(jobPart(envOf(slurmArray("4", "1", "5", "3")), std::nullopt, std::nullopt),
                        "--array=0-2");
}

TEST(JobPart, WithNumShardsTheArrayTaskIdsAreThePartIndices) {
  // A resubmission of parts 4 and 8 of 10 (--array=4,8).
  const JobPart p = jobPart(envOf(slurmArray("8", "4", "8", "2", "4")), std::nullopt, 10);
  EXPECT_EQ(p.index, 8);
  EXPECT_EQ(p.count, 10);
  EXPECT_ERROR_CONTAINS(jobPart(envOf(slurmArray("10", "0", "10", "11")), std::nullopt, 10),
                        "SLURM_ARRAY_TASK_ID=10 is not a part of --num-shards 10");
}

TEST(JobPart, BadSlurmVariablesAreClearErrors) {
  EXPECT_ERROR_CONTAINS(
      jobPart(envOf(slurmArray("two", "0", "2", "3")), std::nullopt, std::nullopt),
      "SLURM_ARRAY_TASK_ID='two' is not an integer");
  EXPECT_ERROR_CONTAINS(jobPart(envOf(slurmArray("1", "0", "2", "3x")), std::nullopt, std::nullopt),
                        "SLURM_ARRAY_TASK_COUNT='3x' is not an integer");
  EXPECT_ERROR_CONTAINS(jobPart(envOf(slurmArray("7", "0", "2", "3")), std::nullopt, std::nullopt),
                        "outside the array 0-2");
  EXPECT_ERROR_CONTAINS(jobPart(envOf({{"SLURM_ARRAY_TASK_ID", "1"}}), std::nullopt, std::nullopt),
                        "SLURM_ARRAY_TASK_MIN is not");
}

TEST(JobPart, KubernetesIndexedJobNeedsNumShards) {
  const JobPart p = jobPart(envOf({{"JOB_COMPLETION_INDEX", "2"}}), std::nullopt, 4);
  EXPECT_EQ(p.index, 2);
  EXPECT_EQ(p.count, 4);
  EXPECT_EQ(p.source, "Kubernetes Indexed Job");
  EXPECT_ERROR_CONTAINS(jobPart(envOf({{"JOB_COMPLETION_INDEX", "2"}}), std::nullopt, std::nullopt),
                        "give --num-shards with the Job's completions");
  EXPECT_ERROR_CONTAINS(jobPart(envOf({{"JOB_COMPLETION_INDEX", "4"}}), std::nullopt, 4),
                        "JOB_COMPLETION_INDEX=4 is not a part of --num-shards 4");
  EXPECT_ERROR_CONTAINS(jobPart(envOf({{"JOB_COMPLETION_INDEX", "-1"}}), std::nullopt, 4),
                        "out of range");
  EXPECT_ERROR_CONTAINS(jobPart(envOf({{"JOB_COMPLETION_INDEX", "1.5"}}), std::nullopt, 4),
                        "not an integer");
}

TEST(JobPart, NoEngineIsOnePartOrTheFlags) {
  const JobPart one = jobPart(envOf({}), std::nullopt, std::nullopt);
  EXPECT_EQ(one.index, 0);
  EXPECT_EQ(one.count, 1);
  EXPECT_EQ(one.describe(), "");
  // --num-shards alone: part 0.
  const JobPart first = jobPart(envOf({}), std::nullopt, 3);
  EXPECT_EQ(first.index, 0);
  EXPECT_EQ(first.count, 3);
  EXPECT_EQ(first.describe(), "part 0 of 3");
}

// ---- training ranks ----

std::map<std::string, std::string> srunStep(int rank, int tasks) {
  return {{"SLURM_JOB_ID", "123456"},
          {"SLURM_STEP_ID", "0"},
          {"SLURM_PROCID", std::to_string(rank)},
          {"SLURM_NTASKS", std::to_string(tasks)},
          {"SLURM_LOCALID", std::to_string(rank % 2)},
          {"SLURM_STEP_NODELIST", "gpu[07-08]"},
          {"SLURM_JOB_NODELIST", "gpu[01-08]"}};
}

TEST(LaunchRole, SrunStepGivesRankWorldLocalRankAndRendezvous) {
  const LaunchRole r = launchRole(envOf(srunStep(3, 4)));
  EXPECT_EQ(r.engine, "srun");
  EXPECT_EQ(r.rank, 3);
  EXPECT_EQ(r.world, 4);
  EXPECT_EQ(r.localRank, 1);
  EXPECT_EQ(r.masterAddr, "gpu07");  // the step's first node, not the job's
  EXPECT_EQ(r.masterPort, kSlurmPortBase + 3456);
  EXPECT_NE(r.describe().find("rank 3 of 4 (local rank 1) from srun"), std::string::npos)
      << r.describe();
  EXPECT_NE(r.describe().find("rendezvous at gpu07:" + std::to_string(r.masterPort)),
            std::string::npos);
  // Without the step's list, the job's.
  auto vars = srunStep(0, 2);
  vars.erase("SLURM_STEP_NODELIST");
  EXPECT_EQ(launchRole(envOf(vars)).masterAddr, "gpu01");
  // MASTER_ADDR and MASTER_PORT given win.
  vars["MASTER_ADDR"] = "10.1.2.3";
  vars["MASTER_PORT"] = "4242";
  const LaunchRole given = launchRole(envOf(vars));
  EXPECT_EQ(given.masterAddr, "10.1.2.3");
  EXPECT_EQ(given.masterPort, 4242);
}

TEST(LaunchRole, TorchrunVariablesWin) {
  auto vars = srunStep(3, 4);
  vars.insert({{"WORLD_SIZE", "2"},
               {"RANK", "1"},
               {"LOCAL_RANK", "1"},
               {"MASTER_ADDR", "host"},
               {"MASTER_PORT", "29400"},
               {"TORCHELASTIC_RUN_ID", "none"}});
  const LaunchRole r = launchRole(envOf(vars));
  EXPECT_EQ(r.engine, "torchrun");
  EXPECT_EQ(r.rank, 1);
  EXPECT_EQ(r.world, 2);
  EXPECT_EQ(r.localRank, 1);
  EXPECT_EQ(r.masterAddr, "host");
  EXPECT_EQ(r.masterPort, 29400);
  EXPECT_FALSE(r.agentStore);
  // torchrun's static rendezvous: its agent serves the store; this is restart 2.
  vars.insert({{"TORCHELASTIC_USE_AGENT_STORE", "True"}, {"TORCHELASTIC_RESTART_COUNT", "2"}});
  const LaunchRole agent = launchRole(envOf(vars));
  EXPECT_TRUE(agent.agentStore);
  EXPECT_EQ(agent.restartCount, 2);
  vars.erase("TORCHELASTIC_USE_AGENT_STORE");
  // Set by hand, without torchrun: the same variables, said so.
  vars.erase("TORCHELASTIC_RUN_ID");
  EXPECT_EQ(launchRole(envOf(vars)).engine, "RANK/WORLD_SIZE");
  // The defaults: 127.0.0.1:29500, local rank 0.
  const LaunchRole d = launchRole(envOf({{"WORLD_SIZE", "2"}, {"RANK", "0"}}));
  EXPECT_EQ(d.masterAddr, "127.0.0.1");
  EXPECT_EQ(d.masterPort, 29500);
  EXPECT_EQ(d.localRank, 0);
}

TEST(LaunchRole, ABatchScriptWithoutSrunIsOneProcessAndSaysSo) {
  // sbatch -n 2 sets SLURM_PROCID=0 and SLURM_NTASKS=2 in the script itself, with no step.
  const LaunchRole r =
      launchRole(envOf({{"SLURM_JOB_ID", "9"}, {"SLURM_PROCID", "0"}, {"SLURM_NTASKS", "2"}}));
  EXPECT_EQ(r.world, 1);
  EXPECT_EQ(r.rank, 0);
  EXPECT_NE(r.describe().find("start it with srun"), std::string::npos) << r.describe();
  const LaunchRole none = launchRole(envOf({}));
  EXPECT_EQ(none.world, 1);
  EXPECT_EQ(none.describe(), "");
}

TEST(LaunchRole, BadVariablesAreClearErrors) {
  EXPECT_ERROR_CONTAINS(launchRole(envOf({{"WORLD_SIZE", "2"}, {"RANK", "2"}})),
                        "RANK=2 must be in [0, WORLD_SIZE=2)");
  EXPECT_ERROR_CONTAINS(launchRole(envOf({{"WORLD_SIZE", "2"}})), "RANK is not");
  EXPECT_ERROR_CONTAINS(launchRole(envOf({{"WORLD_SIZE", "two"}})),
                        "WORLD_SIZE='two' is not an integer");
  EXPECT_ERROR_CONTAINS(launchRole(envOf({{"WORLD_SIZE", "0"}})),
                        "WORLD_SIZE=0 must be at least 1");
  EXPECT_ERROR_CONTAINS(
      launchRole(envOf({{"WORLD_SIZE", "2"}, {"RANK", "0"}, {"MASTER_PORT", "70000"}})),
      "MASTER_PORT=70000 is not a TCP port");
  auto vars = srunStep(0, 2);
  vars["SLURM_PROCID"] = "x";
  EXPECT_ERROR_CONTAINS(launchRole(envOf(vars)), "SLURM_PROCID='x' is not an integer");
  vars = srunStep(2, 2);
  EXPECT_ERROR_CONTAINS(launchRole(envOf(vars)), "SLURM_PROCID=2 must be in [0, SLURM_NTASKS=2)");
  vars = srunStep(0, 2);
  vars["SLURM_STEP_NODELIST"] = "gpu[3-1]";
  EXPECT_ERROR_CONTAINS(launchRole(envOf(vars)), "Slurm host list 'gpu[3-1]'");
  vars = srunStep(0, 2);
  vars.erase("SLURM_STEP_NODELIST");
  vars.erase("SLURM_JOB_NODELIST");
  EXPECT_ERROR_CONTAINS(launchRole(envOf(vars)), "set MASTER_ADDR");
}

TEST(LaunchRole, SlurmPortsStayInTheirRangeAndDifferBetweenNeighbouringJobs) {
  std::mt19937_64 rng(3);
  for (int i = 0; i < 1000; ++i) {
    const long job = static_cast<long>(rng() % 100000000);
    const int port = slurmMasterPort(job);
    EXPECT_GE(port, kSlurmPortBase);
    EXPECT_LT(port, kSlurmPortBase + kSlurmPortCount);
    EXPECT_LT(port, 32768);  // below Linux's ephemeral ports
    EXPECT_NE(port, slurmMasterPort(job + 1));
    EXPECT_EQ(port, slurmMasterPort(job));
  }
}

TEST(LaunchEnvironment, IntegersAreWholeDecimalNumbers) {
  const Environment env = envOf({{"A", "12"}, {"B", " 3"}, {"C", "4 "}, {"D", "0x10"}});
  EXPECT_EQ(environmentInteger(env, "A", 0), 12);
  EXPECT_EQ(environmentInteger(env, "UNSET", 7), 7);
  for (const char* bad : {"B", "C", "D"}) EXPECT_THROW(environmentInteger(env, bad, 0), Error);
}

}  // namespace
}  // namespace paircast
