scene facade1, database db/base-facade1.db
distance: symmetric epipolar distance: the larger of the two point-to-epipolar-line distances, px

| pair | config | inliers | ≤ 1 px | ≤ 2 px | ≤ 4 px | median px | on surface | true ≤ 1 px | true ≤ 2 px | true ≤ 4 px |
|---|---|---|---|---|---|---|---|---|---|---|
| view0.png view1.png | 2 | 1824 | 67.0 % | 69.0 % | 69.4 % | 0.27 | 1824 | 64.3 % | 68.9 % | 69.4 % |
| view0.png view2.png | 2 | 929 | 66.1 % | 71.9 % | 79.7 % | 0.30 | 929 | 61.7 % | 68.7 % | 69.2 % |
| view0.png view3.png | 3 | 774 | 47.5 % | 49.7 % | 50.1 % | 3.27 | 774 | 43.9 % | 49.6 % | 50.1 % |
| view0.png view4.png | 3 | 676 | 33.7 % | 37.6 % | 48.2 % | 4.63 | 676 | 26.2 % | 30.5 % | 30.8 % |
| view1.png view2.png | 3 | 1183 | 69.8 % | 71.8 % | 72.1 % | 0.28 | 1183 | 66.3 % | 71.1 % | 71.9 % |
| view1.png view3.png | 3 | 1018 | 52.2 % | 53.8 % | 54.0 % | 0.78 | 1018 | 49.2 % | 53.5 % | 54.0 % |
| view1.png view4.png | 3 | 814 | 45.2 % | 45.9 % | 46.9 % | 9.82 | 814 | 41.6 % | 45.2 % | 46.6 % |
| view2.png view3.png | 3 | 1252 | 66.4 % | 68.9 % | 69.2 % | 0.35 | 1252 | 63.7 % | 68.5 % | 69.0 % |
| view2.png view4.png | 3 | 882 | 55.7 % | 58.7 % | 62.0 % | 0.57 | 882 | 51.9 % | 56.6 % | 57.5 % |
| view3.png view4.png | 3 | 1365 | 57.7 % | 60.4 % | 61.5 % | 0.48 | 1365 | 54.8 % | 59.5 % | 60.7 % |
| all pairs |  | 10717 | 58.5 % | 61.0 % | 63.0 % | 0.46 | 10717 | 55.0 % | 59.8 % | 60.5 % |
