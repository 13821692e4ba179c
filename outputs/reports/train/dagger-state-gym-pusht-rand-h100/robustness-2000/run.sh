cd /work/main
for pol in nominal rand; do for set in none kp=0.5:0.5 kp=2:2 kv=0.5:0.5 kv=2:2; do
  r=""; [ "$set" != none ] && r="--randomize $set"
  /usr/bin/time -f "$pol $set %e s" .venv/bin/mjx-pusht eval --task gym-pusht --backend cpu --seeds 1000000000:1000002000 --controller policy:/tmp/ana/robust/$pol.msgpack $r --out /tmp/rob2/$pol-${set%%:*} --no-progress --no-rerun --record 0 2>&1 | grep -i "^success\| s$" | tail -2
done; done
