"""The three situations of docs/nonlinear.md: 20 seeds each, `kea nonlinear --json`,
the mean RMS of the EKF, the chosen iterate and the Q-scaled EKF; prints the table rows.

    python3 docs/nonlinear/study.py [KEA]   (KEA: the kea binary, default `kea` on PATH)
"""
import json, os, subprocess, statistics as st, tempfile
import sys
K = sys.argv[1] if len(sys.argv) > 1 else 'kea'
cases={
 'model right': {"y0":[1000,50],"phi":[0,1]},
 'wrong drag law + thrust pulses': {"y0":[1000,50],"phi":[0,1],"f":["x2","-0.05*x2"],"input":["0","4*(signum(t - 6) - signum(t - 10)) - 5*(signum(t - 13) - signum(t - 15))"]},
 'vibration 20 m/s² at 0.5 Hz': {"y0":[1000,50],"phi":[0,1],"input":["0","20*sin(2*PI*0.5*t)"]},
}
for name,truth in cases.items():
  rows=[]
  for seed in range(1,21):
    t=dict(truth); t['seed']=seed
    req={"model":"preset:seed-002","data":{"truth":t},"trace_points":0}
    path=os.path.join(tempfile.gettempdir(),'kea-nonlinear-study.json')
    open(path,'w').write(json.dumps(req))
    r=json.loads(subprocess.run([K,'nonlinear',path,'--json'],capture_output=True,text=True,check=True).stdout)
    ch=r['iterates'][r['i_star']-1]['rms']; ekf=r['ekf']['rms']; q=r['q_scale']['grid'][r['q_scale']['chosen']]['rms']
    rows.append((r['i_star'],ch,ekf,q,r['i_stop_first_increase'],r['best_rms'],r['q_scale']['grid'][r['q_scale']['chosen']]['scale']))
  m=lambda k,i: st.mean(x[k][i] for x in rows)
  istars={i:sum(1 for x in rows if x[0]==i) for i in range(1,7)}
  beats=sum(1 for x in rows if x[1][0]<x[2][0])
  qbeats=sum(1 for x in rows if x[1][0]<x[3][0])
  agree=sum(1 for x in rows if x[4]==x[0]); near=sum(1 for x in rows if abs(x[5][0]-x[0])<=1)
  scales=sorted(set(round(x[6],3) for x in rows))
  print(f"{name}: stop-at-first-increase = i* in {agree}/20; oracle (position) within one of i* in {near}/20; chosen Q scales {scales}")
  print(f"| {name} | {m(2,0):.3f} / {m(2,1):.2f} | {m(1,0):.3f} / {m(1,1):.2f} | {m(3,0):.3f} / {m(3,1):.2f} | {', '.join(f'{k}: {v}' for k,v in istars.items() if v)} | {beats}/20 | {qbeats}/20 |")
