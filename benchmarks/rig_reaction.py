"""The controller's reaction in a rig scene's bag (issue 28/30), per section, from the
publishers' source timestamps (publish_time): when the Pi2 sample (rig/phase) went out,
when the sensor sample that makes the section due went out (the first with stamp
>= t_k - lead - h: the controller answers ``answer_lead`` = 4 ms before the section's
last sample, h = 0.5 ms), when the controller's force pulse went out, and when the
simulator's rig/applied went out; where rig/applied says a prediction or nothing acted:
who was late. ``react`` (pulse out - due sample out) is the controller's compute and
its middleware hops; the 4 ms of answer lead are its deadline.

    .venv/bin/python benchmarks/rig_reaction.py BAGDIR

BAGDIR: a bag of ``benchmarks/bench_rig_scene.py --out DIR`` (DIR/bag), recorded with
the rig topics. Section 0 (the pre-roll) is left out of the percentiles. Results in
docs/benchmarks.md ("The controller's compute per section").
"""
import sys, glob, statistics, bisect
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
LEAD, H = 4e-3, 0.5e-3
f = glob.glob(sys.argv[1] + '/*.mcap')[0]
r = make_reader(open(f, 'rb'), decoder_factories=[DecoderFactory()])
phase, pulse, applied, sens_t, sens_pub = [], {}, {}, [], []
for sch, ch, m, msg in r.iter_decoded_messages(topics=['/rig/phase', '/rig/force_pulse', '/rig/applied', '/rig/sensor']):
    st = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
    if ch.topic == '/rig/phase':
        phase.append((st, m.publish_time))
    elif ch.topic == '/rig/force_pulse':
        pulse[round(msg.wrench.torque.y, 6)] = m.publish_time
    elif ch.topic == '/rig/applied':
        applied[round(msg.wrench.torque.y, 6)] = (msg.wrench.force.z, m.publish_time)
    else:
        sens_t.append(st); sens_pub.append(m.publish_time)
order = sorted(range(len(sens_t)), key=sens_t.__getitem__)
sens_t = [sens_t[i] for i in order]; sens_pub = [sens_pub[i] for i in order]
rows = []
for tk, pub in phase:
    key = round(tk, 6)
    if key not in pulse or key not in applied:
        continue
    i = bisect.bisect_left(sens_t, tk - LEAD - H)
    trig = sens_pub[i] if i < len(sens_pub) else None
    st, apub = applied[key]
    rows.append(dict(tk=tk, st=st, pulse=(pulse[key] - pub) / 1e6, act=(apub - pub) / 1e6,
                     trig=(trig - pub) / 1e6 if trig else float('nan'),
                     react=(pulse[key] - trig) / 1e6 if trig else float('nan')))
def q(name):
    v = sorted(r[name] for r in rows[1:])
    return 'p50 %.3f p99 %.3f max %.3f' % (v[len(v)//2], v[int(.99*len(v))], v[-1])
print('sections', len(rows), '(all times in ms from the Pi2 sample going out)')
for name, what in [('trig', 'sensor sample making it due went out'), ('react', 'controller: pulse out after that sample'),
                   ('pulse', 'pulse went out'), ('act', 'rig/applied went out')]:
    print(f'  {what:42s} {q(name)}')
for r in rows:
    if r['st'] != 0.0:
        print('  status %g at t_k=%.6f: due sample %+.3f, pulse %+.3f (reaction %.3f), applied %+.3f'
              % (r['st'], r['tk'], r['trig'], r['pulse'], r['react'], r['act']))
