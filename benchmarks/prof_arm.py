import cProfile, pstats, sys, time
sys.path.insert(0, "benchmarks")
import bench_vendor_arms as b
from robocritics import Robot, critique, simulate
want = sys.argv[1]
for package, name, path, kw in b.arms():
    if path and want.lower() in name.lower():
        break
robot = Robot.from_urdf(path, **{"tool": "robotiq_2f85", **kw})
scene = b.scene_for(robot.reach_m)
ur = Robot.ur3e(); sur = b.scene_for(ur.reach_m)
for r,s in ((robot,scene),(ur,sur)):
    critique(simulate(b.PROGRAM, s, r))
    t=time.process_time()
    for _ in range(3): ex=simulate(b.PROGRAM, s, r)
    t1=time.process_time()
    for _ in range(3): critique(ex)
    t2=time.process_time()
    print(r.name, "sim ms", (t1-t)/3*1000, "crit ms", (t2-t1)/3*1000, "samples", len(ex.trajectory.t) if hasattr(ex.trajectory,'t') else '?')
pr=cProfile.Profile(); pr.enable()
for _ in range(3): critique(simulate(b.PROGRAM, scene, robot))
pr.disable()
pstats.Stats(pr).sort_stats(sys.argv[2] if len(sys.argv)>2 else "tottime").print_stats(30)
