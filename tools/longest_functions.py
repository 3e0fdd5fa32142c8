#!/usr/bin/env python3
"""The longest functions of the crates (a brace counter, tests/benches/examples left out). Usage: longest_functions.py ROOT [N]"""
import os,re,sys
root=sys.argv[1]
res=[]
for d,_,fs in os.walk(os.path.join(root,'crates')):
    if '/fuzz' in d or '/target' in d: continue
    for f in fs:
        if not f.endswith('.rs'): continue
        p=os.path.join(d,f)
        if '/tests/' in p or '/benches/' in p or '/examples/' in p: continue
        lines=open(p).read().split('\n')
        i=0
        while i<len(lines):
            m=re.match(r'\s*(pub(\([^)]*\))?\s+)?(async\s+)?(const\s+)?fn\s+(\w+)',lines[i])
            if m:
                # find opening brace
                depth=0; started=False; j=i
                while j<len(lines):
                    l=re.sub(r'"(\\.|[^"\\])*"','""',lines[j])
                    l=re.sub(r"'(\\.|[^'\\])'","''",l)
                    l=l.split('//')[0]
                    for ch in l:
                        if ch=='{': depth+=1; started=True
                        elif ch=='}': depth-=1
                    if ';' in l and not started: break
                    if started and depth==0: break
                    j+=1
                if started:
                    res.append((j-i+1, os.path.relpath(p,root), m.group(5), i+1))
            i+=1
# skip test modules? crude: ignore fns inside #[cfg(test)] not handled
res.sort(reverse=True)
for n,p,name,l in res[:int(sys.argv[2]) if len(sys.argv)>2 else 10]:
    print(f"{n:4d} {p}:{l} {name}")
