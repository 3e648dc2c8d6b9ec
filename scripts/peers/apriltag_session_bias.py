#!/usr/bin/env python3
"""Detected corners vs truth.json projected corners per layout (mean outward offset, RMS) for
the first 8 images of a synthetic session at /tmp/h6_sess (needs the detect_json example)."""
import json, subprocess, numpy as np, glob
t=json.load(open('/tmp/h6_sess/truth.json'))
files=[f'/tmp/h6_sess/{im["file"]}' for im in t['images'][:8]]
out=subprocess.run(['/work/tgt/h6/release/examples/detect_json']+files,capture_output=True,text=True).stdout.splitlines()
for im,line in zip(t['images'][:8],out):
    o=json.loads(line)
    for layout in ['reference','headdress']:
        rad=[];err=[]
        for tt in im['targets']:
            if tt['layout']!=layout: continue
            d=[d for d in o['detections'] if d['id']==tt['id']]
            if not d: continue
            dc=np.array(d[0]['corners']); tc=np.array(tt['corners_px'])
            c=tc.mean(0)
            u=(tc-c)/np.linalg.norm(tc-c,axis=1)[:,None]
            rad+=list(((dc-tc)*u).sum(1)); err+=list(np.linalg.norm(dc-tc,axis=1))
        if rad: print(im['file'],layout,'n',len(rad)//4,'mean radial (outward) px %.4f'%np.mean(rad),'rms %.4f'%np.sqrt(np.mean(np.square(err))))
