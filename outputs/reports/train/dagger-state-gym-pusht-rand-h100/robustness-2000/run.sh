# POLICY: dagger-state-gym-pusht-eps-seeds-h100/seed-0/policy (nominal), dagger-state-gym-pusht-rand-h100/seed-0/policy (rand)
for pol in nominal rand; do for set in none kp=0.5:0.5 kp=2:2 kv=0.5:0.5 kv=2:2; do
  r=""; [ "$set" != none ] && r="--randomize $set"
  /usr/bin/time -f "$pol $set %e s" .venv/bin/mjx-pusht eval --task gym-pusht --backend cpu --seeds 1000000000:1000002000 --controller policy:outputs/reports/train/POLICY.msgpack $r --out robustness-2000/$pol-${set%%:*} --no-progress --no-rerun --record 0 2>&1 | grep -i "^success\| s$" | tail -2
done; done
