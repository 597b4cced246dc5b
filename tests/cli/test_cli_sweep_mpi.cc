// dvm sweep under mpirun: the rows spread over the ranks (and over threads within
// them) make the table the same sweep makes on one thread, bit for bit but for the
// timings, with failed rows, with errors
// against a reference run (computed on rank 0), and resumed after the ranks were
// stopped midway; bad input is said once, with exit 2.
//
// The suite needs OpenMPI's mpirun (Debian's openmpi-bin; `make test` installs it).
// Without it the program says so and exits 77, which ctest counts as skipped.
#define BOOST_TEST_MODULE cli_sweep_mpi
#define BOOST_TEST_NO_MAIN
#include <boost/test/unit_test.hpp>

#include "tests/cli/cli_harness.h"
#include "tests/cli/sweep_tables.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <string>
#include <vector>

namespace {

using namespace cli_test;

// mpirun on PATH, or "".
std::string find_mpirun() {
  const char* path = std::getenv("PATH");
  std::istringstream dirs(path ? path : "");
  std::string dir;
  while (std::getline(dirs, dir, ':')) {
    const std::string p = (dir.empty() ? "." : dir) + "/mpirun";
    if (access(p.c_str(), X_OK) == 0) return p;
  }
  return "";
}

// mpirun -n RANKS dvm ARGS: as root (CI) and with more ranks than cores, as the
// machines that run the suites need; the shared-memory transport without the
// single-copy mechanism containers often forbid. In the sanitizer build the ranks run
// without LeakSanitizer (the rest of AddressSanitizer stays on): OpenMPI keeps what
// MPI_Init allocates to the end, in components it has unloaded by then, so the reports
// name no module a suppression could match. The single-process runs each test compares
// with keep the leak check.
std::string rank_asan_options() {
  const char* given = std::getenv("ASAN_OPTIONS");
  return std::string("ASAN_OPTIONS=") + (given && *given ? std::string(given) + ":" : std::string()) +
         "detect_leaks=0";
}
std::vector<std::string> mpirun_args(int ranks, const std::vector<std::string>& args) {
  std::vector<std::string> a = {"-n", std::to_string(ranks), "--oversubscribe", "--allow-run-as-root",
                                "--mca", "btl_vader_single_copy_mechanism", "none",
                                "-x", rank_asan_options(), dvm_binary()};
  a.insert(a.end(), args.begin(), args.end());
  return a;
}
Output mpirun(int ranks, const std::vector<std::string>& args) {
  return run_program(find_mpirun(), mpirun_args(ranks, args));
}

// A harmonic oscillator whose runs differ in cost by a factor of 128 (100 to 12800
// steps); a run with one Newton iteration fails at its first step.
const char* kHarmonic =
    "[system]\nbuiltin = \"harmonic\"\n[initial]\nq = [1.0]\np = [0.5]\n"
    "[integrator]\nmap = \"midpoint\"\nstep = 0.001\nsteps = 100\n";

// The sweep on one thread and under mpirun -n 2 and -n 3 (one row at a time on each
// rank), and -n 2 with --jobs 2 (two rows at a time on each rank): the same tables.
void same_on_ranks(const std::vector<std::string>& args, int status) {
  std::vector<std::string> one = args;
  one.insert(one.end(), {"--jobs", "1", "--out", temp_dir() + "/one"});
  const Output a = dvm(one);
  BOOST_TEST_REQUIRE(a.status == status, a.err);
  const Json expected = parse_json(slurp(temp_dir() + "/one.json"));
  for (const auto& [ranks, jobs] : std::vector<std::pair<int, int>>{{2, 1}, {3, 1}, {2, 2}}) {
    const std::string out = temp_dir() + "/ranks" + std::to_string(ranks) + (jobs > 1 ? "_jobs" + std::to_string(jobs) : "");
    std::vector<std::string> many = args;
    many.insert(many.end(), {"--out", out});
    if (jobs > 1) many.insert(many.end(), {"--jobs", std::to_string(jobs)});
    const Output b = mpirun(ranks, many);
    BOOST_TEST_CONTEXT(ranks << " ranks, --jobs " << jobs) {
      BOOST_TEST(b.status == status, b.err);
      BOOST_TEST(b.out.find("wrote " + out + ".csv") != std::string::npos, b.out);
      BOOST_TEST(untimed_table(parse_json(slurp(out + ".json"))) == untimed_table(expected));
      BOOST_TEST(untimed_csv(slurp(out + ".csv")) == untimed_csv(slurp(temp_dir() + "/one.csv")));
    }
  }
}

}  // namespace

BOOST_AUTO_TEST_CASE(a_sweep_with_failed_runs_is_the_same_on_2_and_3_ranks) {
  const std::string s = write_scene("harmonic.toml", kHarmonic);
  same_on_ranks({"sweep", s, "--vary", "integrator.steps=log:100:12800:8", "--vary",
                 "integrator.max_iterations=[25, 1]", "--vary", "integrator.composition=[none, suzuki5]"},
                3);
  const Json j = parse_json(slurp(temp_dir() + "/ranks3.json"));
  BOOST_TEST(j.at("rows").size() == 32u);
  BOOST_TEST(j.at("failed").get<int>() == 16);
  // a row equals the run done alone
  const Json& row = j.at("rows").at(28);
  const Output alone = dvm({"run", s, "--json", "--no-output", "--set", "integrator.steps=12800", "--set",
                            "integrator.max_iterations=25", "--set", "integrator.composition=\"none\""});
  BOOST_TEST_REQUIRE(alone.status == 0, alone.err);
  BOOST_TEST(row.at("values").at("integrator.steps").get<int>() == 12800);
  BOOST_TEST(untimed(parse_json(alone.out)) == untimed(row.at("run")));
}

BOOST_AUTO_TEST_CASE(errors_against_a_reference_run_are_the_same_on_ranks) {
  const std::string s = write_scene("pendulum.toml",
                                    "[system]\nbuiltin = \"pendulum\"\n[initial]\nq = [1.0]\np = [0.0]\n"
                                    "[integrator]\nmap = \"midpoint\"\nstep = 0.05\nt_end = 2.0\n");
  same_on_ranks({"sweep", s, "--error", "--vary", "integrator.step=[0.05, 0.025]", "--vary",
                 "integrator.composition=[none, suzuki5]"},
                0);
  const Json j = parse_json(slurp(temp_dir() + "/ranks2.json"));
  BOOST_TEST(j.at("references").size() == 1u);
  BOOST_TEST(j.at("rows").at(0).at("error").get<double>() > 0.0);
}

// Stopped by SIGTERM to mpirun (a scheduler's end of a job) once rows are written,
// then resumed on another number of ranks: the table of the uninterrupted sweep. The
// ranks have been seen to go on for about a second after mpirun receives the signal,
// so each long run is sized to last about a second on the machine (and build) running
// the test, measured first: with 8 of them on 2 ranks, the sweep is still running when
// the ranks stop. A fixed step count was not enough: on a fast machine the 3 x 10^6
// steps it had took a quarter of a second a run, and every row was written before the
// ranks stopped.
BOOST_AUTO_TEST_CASE(a_sweep_stopped_on_ranks_resumes) {
  const std::string s = write_long_pendulum("long.toml", 1.0);
  const std::vector<std::string> args = {"sweep", s, "--vary", "integrator.step=log:0.0005:0.002:8", "--vary",
                                         "integrator.max_iterations=[25, 1]"};
  std::vector<std::string> whole = args, cut = args;
  whole.insert(whole.end(), {"--jobs", "1", "--out", temp_dir() + "/whole"});
  const std::string out = temp_dir() + "/cut";
  cut.insert(cut.end(), {"--out", out});
  const Output w = dvm(whole);
  BOOST_TEST_REQUIRE(w.status == 3, w.err);
  const pid_t pid = fork();
  BOOST_TEST_REQUIRE(pid >= 0);
  if (pid == 0) {
    const int null = ::open("/dev/null", O_WRONLY);
    dup2(null, 1);
    dup2(null, 2);
    std::vector<std::string> all = {find_mpirun()};
    for (const std::string& a : mpirun_args(2, cut)) all.push_back(a);
    std::vector<char*> argv;
    for (std::string& a : all) argv.push_back(a.data());
    argv.push_back(nullptr);
    execv(argv[0], argv.data());
    _exit(127);
  }
  std::size_t kept = 0;
  for (int tries = 0; tries < 600000; ++tries) {
    if (file_exists(out + ".json")) {
      const Json j = Json::parse(slurp(out + ".json"), nullptr, false);
      BOOST_TEST_REQUIRE(!j.is_discarded());
      kept = j.at("rows").size();
      if (kept >= 2 && kept < 16) break;
    }
    int status = 0;
    if (waitpid(pid, &status, WNOHANG) == pid) BOOST_FAIL("the sweep ended before it could be stopped");
    const timespec pause{0, 1000000};
    nanosleep(&pause, nullptr);
  }
  BOOST_TEST_REQUIRE(kill(pid, SIGTERM) == 0);
  int status = 0;
  BOOST_TEST_REQUIRE(waitpid(pid, &status, 0) == pid);
  const Json stopped = parse_json(slurp(out + ".json"));
  BOOST_TEST_MESSAGE("stopped with " << stopped.at("rows").size() << " of 16 rows in the table");
  BOOST_TEST_REQUIRE(stopped.at("rows").size() < 16u);
  cut.push_back("--resume");
  const Output r = mpirun(3, cut);
  BOOST_TEST(r.status == 3, r.err);
  BOOST_TEST(untimed_table(parse_json(slurp(out + ".json"))) ==
             untimed_table(parse_json(slurp(temp_dir() + "/whole.json"))));
  BOOST_TEST(untimed_csv(slurp(out + ".csv")) == untimed_csv(slurp(temp_dir() + "/whole.csv")));
}

BOOST_AUTO_TEST_CASE(bad_input_under_mpirun_is_said_once_with_exit_2) {
  const std::string s = write_scene("harmonic.toml", kHarmonic);
  // a value no run takes (found by rank 0 when it checks the rows)
  const Output a = mpirun(2, {"sweep", s, "--vary", "integrator.map=[midpoint, nosuchmap]"});
  BOOST_TEST(a.status == 2, a.err);
  const std::string said = "--vary integrator.map: the value \"nosuchmap\"";
  BOOST_TEST(a.err.find(said) != std::string::npos, a.err);
  BOOST_TEST(a.err.find(said) == a.err.rfind(said), a.err);
  BOOST_TEST(a.out.empty(), a.out);
  // an option every rank refuses while reading the arguments
  const Output b = mpirun(3, {"sweep", s, "--vary", "integrator.step=0.1:0.2:0"});
  BOOST_TEST(b.status == 2, b.err);
  BOOST_TEST(b.err.find("empty range") == b.err.rfind("empty range"), b.err);
  BOOST_TEST(b.err.find("empty range") != std::string::npos, b.err);
  // a bad --jobs, said once
  const Output c = mpirun(2, {"sweep", s, "--jobs", "0", "--vary", "integrator.step=[0.1]"});
  BOOST_TEST(c.status == 2, c.err);
  BOOST_TEST(c.err.find("--jobs: got '0'") != std::string::npos, c.err);
  BOOST_TEST(c.err.find("--jobs") == c.err.rfind("--jobs: got"), c.err);
  // the help says whether this dvm has MPI
  BOOST_TEST(dvm({"sweep", "--help"}).out.find("This dvm was built with MPI.") != std::string::npos);
}

int main(int argc, char* argv[]) {
  if (find_mpirun().empty()) {
    std::printf("test_cli_sweep_mpi: skipped: no mpirun on PATH (OpenMPI: Debian's openmpi-bin, which make test "
                "installs)\n");
    return 77;
  }
  return boost::unit_test::unit_test_main(&init_unit_test, argc, argv);
}
