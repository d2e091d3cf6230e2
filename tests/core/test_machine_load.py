"""core.machine_load: a verdict on whether the machine was busy while something was timed."""

import io

from dsfec_jax.core import machine_load
from dsfec_jax.core.machine_load import Sample

HZ = 100


def jiffies(busy: float, steal: float, idle: float) -> tuple[int, int, int]:
    """/proc/stat's (busy, steal, total) after `busy`, `steal` and `idle` CPU-seconds."""
    return int(busy * HZ), int(steal * HZ), int((busy + steal + idle) * HZ)


def test_a_loaded_machine_is_busy_and_says_why():
    """Load 3.9 on 2 CPUs, the timed process got 0.3 CPU, the CPUs were full and 41 % stolen."""
    before = Sample(wall_s=0.0, process_cpu_s=0.0, load1=3.9, cpus=2, jiffies=(0, 0, 0))
    after = Sample(wall_s=10.0, process_cpu_s=3.0, load1=3.7, cpus=2, jiffies=jiffies(busy=11.8, steal=8.2, idle=0.0))
    v = machine_load.verdict(before, after, hz=HZ)
    assert v["busy"] and v["load1"] == 3.9 and v["steal_percent"] == 41.0
    assert v["others_cpus"] == 0.88  # 11.8 CPU-s busy, 3.0 of them ours, over 10 s
    assert v["text"] == ("busy: load 3.9 on 2 CPUs; the timing process got 30 % of a CPU; "
                         "the CPUs were full and other processes used 0.9 of them; 41 % steal")
    out = io.StringIO()
    machine_load.warn(v, "the test's timing", stream=out)
    assert out.getvalue().startswith("warning: the machine was busy during the test's timing (load 3.9 on 2 CPUs;")


def test_an_idle_machine_is_not_busy_and_prints_nothing():
    """One CPU of two used, by the timed process alone; load 1.0."""
    before = Sample(0.0, 0.0, 0.9, 2, (0, 0, 0))
    after = Sample(10.0, 9.8, 1.0, 2, jiffies(busy=9.9, steal=0.0, idle=10.1))
    v = machine_load.verdict(before, after, hz=HZ)
    assert not v["busy"] and v["reasons"] == [] and v["steal_percent"] == 0.0
    assert v["text"] == "idle: load 1.0 on 2 CPUs; other processes used 0.0 CPUs"
    out = io.StringIO()
    machine_load.warn(v, "the test's timing", stream=out)
    assert out.getvalue() == ""


def test_without_proc_stat_the_verdict_names_what_it_skipped(tmp_path):
    assert machine_load.read_jiffies(tmp_path / "missing") is None
    v = machine_load.verdict(Sample(0.0, 0.0, None, 4), Sample(1.0, 1.0, None, 4))
    assert not v["busy"] and "no /proc/stat" in v["unchecked"] and "load1" not in v
    stat = tmp_path / "stat"  # user nice system idle iowait irq softirq steal guest guest_nice
    stat.write_text("cpu  100 5 20 800 10 1 2 30 0 0\ncpu0 1 1 1 1 1 1 1 1 0 0\n")
    assert machine_load.read_jiffies(stat) == (128, 30, 968)


def test_watch_samples_around_a_block():
    with machine_load.watch() as load:
        sum(i * i for i in range(200_000))  # CPU-bound: the process keeps its CPU on an idle machine
    v = load.verdict
    assert v["wall_s"] > 0 and v["cpus"] >= 1 and isinstance(v["busy"], bool) and v["text"].split(":")[0] in ("busy", "idle")
